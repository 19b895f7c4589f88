"""Fuzz parameter notation, value types and value conversion with random types and scalings.

Property: parse_parameter, parse_type, Scaling.scale/conversion, check_limits,
encode_value and decode_value raise nothing but the protocol's errors
(LocalProtocolError, RemoteProtocolError); decode_text never raises; a
parsed parameter has a PNU of 0-65535 and an index of 0-255.

Run: .venv/bin/python fuzz/fuzz_notation.py -max_total_time=60 -timeout=10 var/fuzz/notation
"""

from __future__ import annotations

import math
import sys

import atheris

with atheris.instrument_imports():
    from pkwbus.protocol import values as params
    from pkwbus.protocol.errors import ProtocolError
    from pkwbus.protocol.pkw import Width

import _support

TYPES = tuple(params.ValueType)
ROUNDINGS = tuple(params.Rounding)
INDEXES = tuple(params.CONVERSION_FACTORS)

# Every finding of these harnesses (see docs/fuzzing.md) is fixed; a new one
# would be listed here while it is open.
KNOWN: tuple[_support.Known, ...] = ()


def value(fdp: atheris.FuzzedDataProvider) -> float | int | str:
    kind = fdp.ConsumeIntInRange(0, 3)
    if kind == 0:
        return int(fdp.ConsumeInt(8))
    if kind == 1:
        return float(fdp.ConsumeRegularFloat() if fdp.ConsumeBool() else fdp.ConsumeFloat())
    text = str(fdp.ConsumeUnicodeNoSurrogates(fdp.ConsumeIntInRange(0, 24)))
    if kind == 2:
        return text
    # number-shaped text, exponents well beyond any parameter's range included
    mantissa = f"{fdp.ConsumeInt(4)}.{fdp.ConsumeIntInRange(0, 9999)}"
    return f"{mantissa}e{fdp.ConsumeIntInRange(-6000, 6000)}"


def scaling(fdp: atheris.FuzzedDataProvider) -> params.Scaling:
    pick = fdp.ConsumeIntInRange(0, 2)
    if pick == 0:
        return params.UNSCALED
    if pick == 1:
        return params.Scaling.conversion(INDEXES[fdp.ConsumeIntInRange(0, len(INDEXES) - 1)])
    return params.Scaling.scale(fdp.ConsumeFloat())


def check(fdp: atheris.FuzzedDataProvider) -> None:
    what = fdp.ConsumeIntInRange(0, 5)
    if what == 0:
        ref = params.parse_parameter(fdp.ConsumeUnicodeNoSurrogates(fdp.remaining_bytes()))
        assert 0 <= ref.pnu <= params.MAX_PNU and (ref.index is None or 0 <= ref.index <= 255)
    elif what == 1:
        params.parse_type(fdp.ConsumeUnicodeNoSurrogates(fdp.remaining_bytes()))
    elif what == 2:
        vtype = TYPES[fdp.ConsumeIntInRange(0, len(TYPES) - 1)]
        rounding = ROUNDINGS[fdp.ConsumeIntInRange(0, 1)]
        scale = scaling(fdp)
        raw = params.encode_value(value(fdp), vtype, scale, rounding)
        width = vtype.width
        assert width is not None
        assert 0 <= raw < 1 << width.value, raw
        if vtype is params.ValueType.F32 and raw & 0x7F800000 == 0x7F800000:
            raise AssertionError(f"F-PAR-4 f32 bits {raw:#010x} are not a finite number")
    elif what == 3:
        width = Width.WORD if fdp.ConsumeBool() else Width.DWORD
        raw = fdp.ConsumeIntInRange(0, (1 << width.value) - 1)
        vtype = None if fdp.ConsumeBool() else TYPES[fdp.ConsumeIntInRange(0, len(TYPES) - 1)]
        number = params.decode_value(raw, width, vtype, scaling(fdp))
        assert isinstance(number, int | float)
    elif what == 4:
        low = fdp.ConsumeFloat() if fdp.ConsumeBool() else None
        high = fdp.ConsumeFloat() if fdp.ConsumeBool() else None
        low = low if low is None or math.isfinite(low) else None
        high = high if high is None or math.isfinite(high) else None
        params.check_limits(value(fdp), low, high, "Hz")
    else:
        params.decode_text(fdp.ConsumeBytes(fdp.remaining_bytes()))


def test_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    try:
        check(fdp)
    except ProtocolError:
        pass
    except Exception as exc:
        _support.tolerate(exc, KNOWN)


def main() -> None:
    _support.write_seeds([b"\x00\x0016-13[2]", b"\x00\x00r0021", b"\x02\x04\x01\x00\x03"])
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
