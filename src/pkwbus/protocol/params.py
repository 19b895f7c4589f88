"""Parameter notation, value types and conversion-index scaling.

Notation (everywhere: CLI, config, API): ``16-13`` and ``3-41`` (Danfoss
group-number style: PNU 1613, 341), ``1613`` (plain PNU), ``r0021``,
``p1082``, ``P7841`` (Siemens style, case-insensitive), each optionally with
an index: ``P7841[2]``.
"""

from __future__ import annotations

import enum
import math
import re
import struct
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from fractions import Fraction
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw import Width


class ParameterNotationError(LocalProtocolError):
    """Text that is not a parameter in any notation pkwbus knows."""


MAX_PNU: Final = 0xFFFF
MAX_INDEX: Final = 0xFF

_NOTATION = re.compile(
    r"""^(?:
        (?P<group>[0-9]{1,2})-(?P<number>[0-9]{2})
      | (?P<prefix>[rRpP])(?P<siemens>[0-9]{1,5})
      | (?P<plain>[0-9]{1,5})
    )(?:\[(?P<index>[0-9]{1,3})\])?$""",
    re.VERBOSE,
)
_HINT = "write it as 16-13, 1613, r0021 or P7841[2]"


@dataclass(frozen=True, slots=True)
class ParameterRef:
    """A parameter as written: its PNU, its index if one was given, and its name as written."""

    pnu: int
    index: int | None
    name: str

    def __str__(self) -> str:
        return self.name if self.index is None else f"{self.name}[{self.index}]"


def parse_parameter(text: str) -> ParameterRef:
    """Parse the notation; a clear :class:`ParameterNotationError` for anything else."""
    written = text.strip()
    found = _NOTATION.match(written)
    if found is None:
        raise ParameterNotationError(f"{text!r} is not a parameter: {_HINT}")
    if found["group"] is not None:
        pnu = int(found["group"] + found["number"])
        name = f"{int(found['group'])}-{found['number']}"
    elif found["siemens"] is not None:
        pnu = int(found["siemens"])
        name = found["prefix"] + found["siemens"]
    else:
        pnu = int(found["plain"])
        name = found["plain"]
    if pnu > MAX_PNU:
        raise ParameterNotationError(f"{text!r}: parameter number {pnu} is above {MAX_PNU}")
    index = None if found["index"] is None else int(found["index"])
    if index is not None and index > MAX_INDEX:
        raise ParameterNotationError(f"{text!r}: index {index} is above {MAX_INDEX}")
    return ParameterRef(pnu, index, name)


# ------------------------------------------------------------------ types


class ValueType(enum.StrEnum):
    U16 = "u16"
    I16 = "i16"
    U32 = "u32"
    I32 = "i32"
    F32 = "f32"
    TEXT = "text"

    @property
    def width(self) -> Width | None:
        """Word or double word on the wire; None for text."""
        if self in (ValueType.U16, ValueType.I16):
            return Width.WORD
        if self is ValueType.TEXT:
            return None
        return Width.DWORD

    @property
    def bounds(self) -> tuple[int, int]:
        return _BOUNDS[self]


_BOUNDS = {
    ValueType.U16: (0, 0xFFFF),
    ValueType.I16: (-0x8000, 0x7FFF),
    ValueType.U32: (0, 0xFFFFFFFF),
    ValueType.I32: (-0x80000000, 0x7FFFFFFF),
}


# Data type numbers of description element 1: Danfoss [D5, D6] and PROFIdrive
# share them. Types without a ValueType travel as the nearest one.
DATA_TYPES: Final = {
    1: ("Boolean", ValueType.U16),
    2: ("Int8", ValueType.I16),
    3: ("Int16", ValueType.I16),
    4: ("Int32", ValueType.I32),
    5: ("UInt8", ValueType.U16),
    6: ("UInt16", ValueType.U16),
    7: ("UInt32", ValueType.U32),
    8: ("FloatingPoint32", ValueType.F32),
    9: ("text", ValueType.TEXT),
    10: ("byte string", None),
    13: ("time difference", ValueType.U32),
    33: ("N2", ValueType.I16),
    35: ("bit sequence", ValueType.U16),
}


def parse_type(text: str) -> ValueType:
    try:
        return ValueType(text.strip().lower())
    except ValueError:
        known = " ".join(t.value for t in ValueType)
        raise LocalProtocolError(f"unknown type {text!r} (known: {known})") from None


# ---------------------------------------------------------------- scaling

CONVERSION_FACTORS: Final = {
    **{i: Fraction(10) ** i for i in range(-7, 7)},
    67: Fraction(1, 60),
    74: Fraction(3600),
    75: Fraction(3_600_000),
    100: Fraction(1),
}


class Rounding(enum.Enum):
    NEAREST = "nearest"  # half away from zero
    EXACT = "exact"  # refuse values the raw number cannot represent


@dataclass(frozen=True, slots=True)
class Scaling:
    """Engineering value = raw number * factor."""

    factor: Fraction = Fraction(1)

    @classmethod
    def conversion(cls, index: int) -> Scaling:
        try:
            return cls(CONVERSION_FACTORS[index])
        except KeyError:
            raise LocalProtocolError(
                f"conversion index {index} is not one of -7..6, 67, 74, 75, 100"
            ) from None

    @classmethod
    def scale(cls, factor: float) -> Scaling:
        if not math.isfinite(factor) or factor == 0:
            raise LocalProtocolError(f"scale {factor} must be a finite number other than 0")
        return cls(Fraction(Decimal(repr(factor))))


UNSCALED = Scaling()


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
    """An engineering value as the raw PWE number (unsigned bit pattern) of ``vtype``."""
    if vtype is ValueType.TEXT:
        raise LocalProtocolError("text values are written as text, not as a number")
    if vtype is ValueType.F32:
        single = _float(value) / float(scaling.factor)
        if not math.isfinite(single):
            raise LocalProtocolError(f"{value} is outside the f32 range")
        return _f32_bits(single)
    number = _fraction(value) / scaling.factor
    if number.denominator != 1 and rounding is Rounding.EXACT:
        step = float(scaling.factor)
        raise LocalProtocolError(f"{value} is not a multiple of the parameter's resolution {step}")
    raw = _round_half_away(number)
    low, high = vtype.bounds
    if not low <= raw <= high:
        raise LocalProtocolError(
            f"{value} is raw {raw}, outside the {vtype.value} range {low}..{high}"
        )
    return raw & (0xFFFF if vtype.width is Width.WORD else 0xFFFFFFFF)


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
    else:
        bits = width.value
        number = raw - (1 << bits) if vtype in _SIGNED and raw >> (bits - 1) & 1 else raw
    if scaling.factor == 1:
        return number
    if isinstance(number, float):
        return number * float(scaling.factor)
    scaled = number * scaling.factor
    return int(scaled) if scaled.denominator == 1 else float(scaled)


_SIGNED = frozenset({ValueType.I16, ValueType.I32})


def decode_text(data: bytes) -> str:
    """Text from a drive: Latin-1, trailing NULs and blanks dropped."""
    return data.decode("latin-1").rstrip("\x00 ")


def encode_text(text: str) -> bytes:
    try:
        return text.encode("latin-1")
    except UnicodeEncodeError:
        raise LocalProtocolError(f"{text!r} has characters a drive cannot show") from None
