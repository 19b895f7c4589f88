"""Engineering values to raw numbers and back: limits, exact encoding, f32, text.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for a value that cannot be
encoded and :class:`~pkwbus.protocol.errors.RemoteProtocolError` for an answer of the
wrong kind.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from fractions import Fraction
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.values.types import UNSCALED, Rounding, Scaling, ValueType, Width

__all__ = [
    "F32_MIN_NORMAL",
    "MAX_DECIMAL_EXPONENT",
    "check_limits",
    "decode_text",
    "decode_value",
    "encode_exact",
    "encode_text",
    "encode_value",
]


# No parameter value needs more: f32 ends near 3.4e38, its smallest steps near 1e-45.
MAX_DECIMAL_EXPONENT: Final = 60


def _fraction(value: float | int | str) -> Fraction:
    text = str(value).strip()
    if len(text) > 100:
        raise LocalProtocolError(f"{text[:20]}... is not a parameter value (too long)")
    try:
        number = Decimal(text)
    except InvalidOperation:
        raise LocalProtocolError(f"{value!r} is not a number") from None
    if not number.is_finite():
        raise LocalProtocolError(f"{value!r} is not a finite number")
    if number and abs(number.adjusted()) > MAX_DECIMAL_EXPONENT:
        raise LocalProtocolError(f"{value!r} is out of any parameter's range")
    return Fraction(number)


def _float(value: float | int | str) -> float:
    number = value if isinstance(value, float) else float(_fraction(value))
    if not math.isfinite(number):
        raise LocalProtocolError(f"{value!r} is not a finite number")
    return number


def _round_half_away(x: Fraction) -> int:
    floor = math.floor(abs(x) + Fraction(1, 2))
    return floor if x >= 0 else -floor


def check_limits(
    value: float | int | str, minimum: float | None, maximum: float | None, unit: str = ""
) -> None:
    """A value outside the parameter's limits is an input error."""
    number = _fraction(value)
    suffix = f" {unit}" if unit else ""
    if minimum is not None and number < _fraction(minimum):
        raise LocalProtocolError(f"{value}{suffix} is below the minimum {minimum}{suffix}")
    if maximum is not None and number > _fraction(maximum):
        raise LocalProtocolError(f"{value}{suffix} is above the maximum {maximum}{suffix}")


def encode_value(
    value: float | int | str,
    vtype: ValueType,
    scaling: Scaling = UNSCALED,
    rounding: Rounding = Rounding.NEAREST,
) -> int:
    """An engineering value as the raw PWE number (unsigned bit pattern) of ``vtype``.

    ``Rounding.NEAREST`` takes the nearest raw number (for the simulated drives'
    measurements); ``Rounding.EXACT`` is :func:`encode_exact`, the rule for writes.
    """
    if rounding is Rounding.EXACT:
        return encode_exact(value, vtype, scaling)
    if vtype is ValueType.TEXT:
        raise LocalProtocolError("text values are written as text, not as a number")
    if vtype is ValueType.F32:
        single = _float(value) / float(scaling.factor)
        if not math.isfinite(single):
            raise LocalProtocolError(f"{value} is outside the f32 range")
        return _f32_bits(single)
    raw = _round_half_away(_fraction(value) / scaling.factor)
    _check_raw(value, raw, vtype)
    return raw & _mask(vtype)


def _check_raw(value: float | int | str, raw: int, vtype: ValueType) -> None:
    low, high = vtype.bounds
    if not low <= raw <= high:
        raise LocalProtocolError(
            f"{value} is raw {raw}, outside the {vtype.value} range {low}..{high}"
        )


def _mask(vtype: ValueType) -> int:
    return 0xFFFF if vtype.width is Width.WORD else 0xFFFFFFFF


# ------------------------------------------------------------ exact values


def encode_exact(
    value: float | int | str,
    vtype: ValueType,
    scaling: Scaling = UNSCALED,
    *,
    parameter: str = "",
    minimum: float | None = None,
    maximum: float | None = None,
    unit: str = "",
) -> int:
    """The raw PWE number that holds ``value`` exactly, within the limits; else an
    input error naming the nearest values that can be written.

    The rule for every write, from the command line and the API alike:

    - an integer type holds whole multiples of the scaling's step (conversion
      index -2: 12.34, not 12.345);
    - an f32 holds ``value`` when the single nearest to it is ``value`` itself,
      or when ``value`` is the shortest decimal naming that single, as floats
      are written everywhere (0.1 is the single 0.100000001...: fine;
      0.30000001 names no single of its own: refused), or when it is the single
      as pkwbus reads it (0.10000000149011612). A value other than 0
      that would become 0 or a subnormal (below 1.1754944e-38, where an f32
      loses its precision) is refused.
    """
    if vtype is ValueType.TEXT:
        raise LocalProtocolError("text values are written as text, not as a number")
    check_limits(value, minimum, maximum, unit)
    number = _fraction(value)
    limits = _Limits(
        None if minimum is None else _fraction(minimum),
        None if maximum is None else _fraction(maximum),
    )
    shown = str(value).strip()
    where = f" for {parameter}" if parameter else ""
    if vtype is ValueType.F32:
        return _exact_f32(number, scaling.factor, shown, where, limits)
    raw = number / scaling.factor
    if raw.denominator == 1:
        _check_raw(shown, int(raw), vtype)
        return int(raw) & _mask(vtype)
    low, high = vtype.bounds
    near = [n for n in (math.floor(raw), math.ceil(raw)) if low <= n <= high]
    if not near:
        _check_raw(shown, _round_half_away(raw), vtype)
    values = [n * scaling.factor for n in near]
    raise LocalProtocolError(
        f"{shown} is not a multiple of {_fraction_text(scaling.factor, step=True)}{where}: "
        + _nearest([_fraction_text(v) for v in values if limits.hold(v)])
    )


@dataclass(frozen=True, slots=True)
class _Limits:
    low: Fraction | None
    high: Fraction | None

    def hold(self, value: Fraction) -> bool:
        return (self.low is None or value >= self.low) and (self.high is None or value <= self.high)


def _nearest(texts: list[str]) -> str:
    if not texts:
        return "no value near it is within the limits"
    return "nearest " + " or ".join(texts)


F32_MIN_NORMAL: Final = Fraction(1, 2**126)
_F32_EXPONENT = 0x7F800000


def _exact_f32(number: Fraction, factor: Fraction, shown: str, where: str, limits: _Limits) -> int:
    x = number / factor
    if x == 0:
        return 0
    bits = _f32_nearest(x)
    if bits is None:
        raise LocalProtocolError(f"{shown} is outside the f32 range{where}")
    single = _f32_fraction(bits)
    if abs(single) < F32_MIN_NORMAL:
        smallest = 0x00800000 | (bits & 0x80000000)
        held = "0" if single == 0 else f"{float(single * factor):.8g}"
        near = {"0": Fraction(0)}
        near[_decimal_text(_f32_shortest(smallest, factor))] = _f32_fraction(smallest) * factor
        raise LocalProtocolError(
            f"{shown} is below the smallest f32 (it would become {held}){where}: "
            + _nearest([text for text, v in near.items() if limits.hold(v)])
        )
    if single == x or number in (Fraction(_f32_shortest(bits, factor)), _as_read(bits, factor)):
        return bits
    below, above = (bits, _f32_next(bits, True)) if single < x else (_f32_next(bits, False), bits)
    texts = []
    for side in (below, above):
        if side is None or (abs(_f32_fraction(side)) < F32_MIN_NORMAL and side & 0x7FFFFFFF):
            continue  # a subnormal is no exact value
        if limits.hold(_f32_fraction(side) * factor):
            texts.append(_decimal_text(_f32_shortest(side, factor)))
    raise LocalProtocolError(f"{shown} has no exact f32 value{where}: " + _nearest(texts))


def _as_read(bits: int, factor: Fraction) -> Fraction:
    """The single as pkwbus reads and shows it (a double: 0.10000000149011612)."""
    shown = decode_value(bits, Width.DWORD, ValueType.F32, Scaling(factor))
    return Fraction(Decimal(repr(shown)))


def _f32_fraction(bits: int) -> Fraction:
    return Fraction(struct.unpack(">f", bits.to_bytes(4, "big"))[0])


def _f32_next(bits: int, up: bool) -> int | None:
    """The single next to ``bits`` towards +inf (``up``) or -inf; None past the range."""
    if bits & 0x7FFFFFFF == 0:
        after = 0x00000001 if up else 0x80000001
    elif (bits >> 31 == 0) == up:
        after = bits + 1
    else:
        after = bits - 1
    return None if after & _F32_EXPONENT == _F32_EXPONENT else after


def _f32_nearest(x: Fraction) -> int | None:
    """The bits of the single nearest ``x`` (ties to even); None beyond the f32 range."""
    try:
        bits = int.from_bytes(struct.pack(">f", float(x)), "big")
    except OverflowError:
        return None
    if bits & _F32_EXPONENT == _F32_EXPONENT:
        return None
    # float(x) rounds to a double, packing rounds again: settle on the nearest single.
    best = bits
    for other in (_f32_next(bits, True), _f32_next(bits, False)):
        if other is None:
            continue
        gap, best_gap = abs(_f32_fraction(other) - x), abs(_f32_fraction(best) - x)
        if gap < best_gap or (gap == best_gap and other & 1 == 0):
            best = other
    return best


def _f32_shortest(bits: int, factor: Fraction) -> Decimal:
    """The shortest decimal whose nearest single, after the scaling, is ``bits``."""
    value = _f32_fraction(bits) * factor
    if value == 0:
        return Decimal(0)
    exponent = math.floor(math.log10(abs(float(value))))
    while Fraction(10) ** exponent > abs(value):
        exponent -= 1
    while Fraction(10) ** (exponent + 1) <= abs(value):
        exponent += 1
    for digits in range(1, 41):
        shift = exponent - digits + 1
        candidate = Decimal(round(value / Fraction(10) ** shift)).scaleb(shift)
        if _f32_nearest(Fraction(candidate) / factor) == bits:
            return candidate
    return candidate


def _fraction_text(value: Fraction, *, step: bool = False) -> str:
    """An exact decimal when there is one (0.01, 32.99560546875); else 1/60 for a
    step and an approximation (~0.01666667) for a value."""
    denominator, twos, fives = value.denominator, 0, 0
    while denominator % 2 == 0:
        denominator, twos = denominator // 2, twos + 1
    while denominator % 5 == 0:
        denominator, fives = denominator // 5, fives + 1
    if denominator != 1:
        return str(value) if step else f"~{float(value):.7g}"
    places = max(twos, fives)
    return _decimal_text(Decimal(value.numerator * 10**places // value.denominator).scaleb(-places))


def _decimal_text(number: Decimal) -> str:
    """1.5, 0.01, 16777216, 1.1754944e-38: plain unless very large or very small."""
    number = number.normalize()
    if number.is_zero():
        return "0"
    if -7 <= number.adjusted() <= 15:
        return format(number, "f")
    return format(number, "e")


def _f32_bits(number: float) -> int:
    try:
        packed = struct.pack(">f", number)
    except OverflowError:
        raise LocalProtocolError(f"{number} is outside the f32 range") from None
    return int.from_bytes(packed, "big")


def decode_value(
    raw: int, width: Width, vtype: ValueType | None, scaling: Scaling = UNSCALED
) -> int | float:
    """The engineering value of a raw PWE number answered as ``width``.

    Without a type the value is the raw unsigned number. A signed type is
    sign-extended from the width the drive answered with; an f32 parameter
    answered with a word is the peer's error, never a guessed number.
    """
    if vtype is None:
        number: int | float = raw
    elif vtype is ValueType.F32:
        if width is not Width.DWORD:
            raise RemoteProtocolError("an f32 parameter was answered with a word")
        number = struct.unpack(">f", raw.to_bytes(4, "big"))[0]
    elif vtype is ValueType.TEXT:
        raise RemoteProtocolError("a text parameter was answered with a number")
    elif vtype in _SIGNED:
        bits = 32 if width is Width.DWORD else 16
        number = raw - (1 << bits) if raw >> (bits - 1) & 1 else raw
    else:
        number = raw
    if scaling.factor == 1:
        return number
    factor = scaling.factor
    if isinstance(number, float):
        return number * float(factor)
    # number * factor as a Fraction would give, without making one: a whole number, else
    # the quotient correctly rounded (as float() of the Fraction).
    scaled, denominator = number * factor.numerator, factor.denominator
    return scaled // denominator if scaled % denominator == 0 else scaled / denominator


_SIGNED = frozenset({ValueType.I16, ValueType.I32})


def decode_text(data: bytes) -> str:
    """Text from a drive: Latin-1, trailing NULs and blanks dropped."""
    return data.decode("latin-1").rstrip("\x00 ")


def encode_text(text: str) -> bytes:
    try:
        return text.encode("latin-1")
    except UnicodeEncodeError:
        raise LocalProtocolError(f"{text!r} has characters a drive cannot show") from None
