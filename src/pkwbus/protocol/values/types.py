"""Value types (u16 ... f32, text), description data types and conversion-index scaling.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for an unknown type,
conversion index or scale.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from decimal import Decimal
from fractions import Fraction
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError

__all__ = [
    "CONVERSION_FACTORS",
    "DATA_TYPES",
    "UNSCALED",
    "Rounding",
    "Scaling",
    "ValueType",
    "Width",
    "parse_type",
]


# ------------------------------------------------------------------ types


class Width(enum.Enum):
    """How wide a value travels: a word (16 bits) or a double word (32 bits)."""

    WORD = 16
    DWORD = 32


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

    @property
    def whole(self) -> bool:
        """A whole-number type (u16, i16, u32, i32): the ones with bounds."""
        return self in _BOUNDS


_BOUNDS = {
    ValueType.U16: (0, 0xFFFF),
    ValueType.I16: (-0x8000, 0x7FFF),
    ValueType.U32: (0, 0xFFFFFFFF),
    ValueType.I32: (-0x80000000, 0x7FFFFFFF),
}


# Data type numbers of description element 1: Danfoss (FC 202 Design Manual, PKW
# and data types; FC 300 Design Manual) and PROFIdrive
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
