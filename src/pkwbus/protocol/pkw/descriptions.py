"""What a drive says of one of its parameters: its description elements (PKW request AK 4).

Two forms of the same element numbers:

- **Danfoss FC** (Danfoss FC 300 Design Guide, "Read parameter description";
  FC 300 Design Manual, conversion index): 1 data type (low byte), 2 number of
  array elements, 4 conversion index (high byte, signed) and unit index (low
  byte), 6 name (text), 7 low limit, 8 high limit, as raw values of the
  parameter's type.
- **PROFIdrive** (Siemens USS and PROFIdrive channels, Danfoss PROFIBUS PCV;
  Danfoss VLT PROFIBUS manual MG.33.C4.02, section 5 "Parameter description",
  and VLT FCD 302 PROFIBUS manual, tables 5.10 and 5.11): 1 identifier (bits
  0-7 data type, bit 8 "standardisation factor and variable attribute not
  relevant", bit 9 read-only, bit 12 "parameter has been changed from factory
  setting" (FC 300 PROFIBUS manual MG.33.C2.02, "Identifier ID"), bit 14
  array), 2 number of array elements (or
  string length), 4 variable attribute (first byte the variable index, the
  physical unit; second byte the conversion index), 6 name (16 characters),
  7 lower and 8 upper limit (32 bit signed).

What a drive says of its settings (FC 300 Design Guide MG.33.B3.22, "Default
value (index 20)" and "Additional characteristics (index 21)"): FC element 20
is the parameter's default value, "which is the factory setting", of the
parameter's own data type; element 21 answers bits in PWE low: 0-2 special
default, upper and lower limit (power-unit dependent values), 7-8 LCP access,
9 no bus access, 10 and 11 "can only be read over the bus", 13 "cannot be
changed while running", 15 depends on the power unit. A PROFIdrive drive says
instead, in its identifier's bit 12, whether the value differs from the
factory setting; it has no default-value element (MG.33.C2.02 lists elements
1-12).

The unit of a scaled value is the base unit of its size (variable) index, the
row of conversion index 0 in the size attribute table of MG.33.C4.02, section
6.4.3: a scaled value is in that unit (raw 1000 of a time with index -3 is
1.000 s). The FC protocol's unit index follows the unit table of the FC 300
Design Guide ("Read parameter description"), which differs in two rows:
energy (8) is in J, temperature (17) in K, and in degrees Celsius only with
conversion index 100. Rotation (index 11) is left out: MG.33.C4.02 lists it
only with conversion index 67 at factor 1, where the FC design manuals give
67 = 1/60.

Pure: no I/O, no clock. Nothing here raises: an element the drive did not
give, or gave in a form this module cannot read, is simply not known.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import Command, Dialect
from pkwbus.protocol.values.encoding import decode_text
from pkwbus.protocol.values.types import (
    CONVERSION_FACTORS,
    DATA_TYPES,
    UNSCALED,
    Scaling,
    ValueType,
)

__all__ = [
    "BASE_UNITS",
    "CHARACTERISTICS",
    "DATA_TYPE",
    "FACTORY",
    "FC_BASE_UNITS",
    "LIMITS",
    "NAME",
    "SCALING",
    "SIZE",
    "Characteristics",
    "DescriptionForm",
    "DriveDescription",
    "changed_from_factory",
    "elements_to_read",
    "factory_raw",
    "form_of",
    "read_elements",
]

DATA_TYPE: Final = 1  # FC: data type; PROFIdrive: identifier (ID)
SIZE: Final = 2  # number of array elements (PROFIdrive: or string length)
SCALING: Final = 4  # FC: conversion and unit index; PROFIdrive: variable attribute
NAME: Final = 6
LIMITS: Final = (7, 8)
FACTORY: Final = 20  # FC: the default value, "which is the factory setting"
CHARACTERISTICS: Final = 21  # FC: additional characteristics, bits in PWE low

#: Size (variable) index -> the base unit of a scaled value (Danfoss VLT PROFIBUS
#: manual MG.33.C4.02, 6.4.3 "Size attribute", the rows of conversion index 0).
BASE_UNITS: Final[Mapping[int, str]] = {
    0: "",  # no dimension
    4: "s",
    8: "Wh",
    9: "W",
    16: "Nm",
    17: "°C",
    21: "V",
    22: "A",
    23: "Ohm",
    24: "%",
    27: "%",
    28: "Hz",
}

#: The same for the FC protocol's unit index (FC 300 Design Guide, "Read parameter description").
FC_BASE_UNITS: Final[Mapping[int, str]] = {**BASE_UNITS, 8: "J", 17: "K"}
_FC_CELSIUS: Final = 100  # conversion index that makes size 17 degrees Celsius on FC

# PROFIdrive identifier bits (MG.33.C4.02 section 5; VLT FCD 302 PROFIBUS manual, table 5.11).
_ID_NOT_SCALED = 1 << 8
_ID_READ_ONLY = 1 << 9
_ID_CHANGED = 1 << 12  # "parameter has been changed from factory setting" (MG.33.C2.02)
_ID_ARRAY = 1 << 14


class DescriptionForm(enum.StrEnum):
    DANFOSS_FC = "fc"
    PROFIDRIVE = "profidrive"


def form_of(dialect: Dialect) -> DescriptionForm | None:
    """How ``dialect`` describes its parameters; None when it has no AK 4 (Hitachi SJ-PB)."""
    if not dialect.has(Command.READ_DESCRIPTION):
        return None
    return DescriptionForm.DANFOSS_FC if dialect.name == "fc" else DescriptionForm.PROFIDRIVE


def elements_to_read(*, limits: bool) -> tuple[int, ...]:
    """The elements a master reads: type, size, scaling and name; the limits only when
    they matter (a parameter that may be written)."""
    head = (DATA_TYPE, SIZE, SCALING, NAME)
    return head + LIMITS if limits else head


@dataclass(frozen=True, slots=True)
class DriveDescription:
    """What the drive said of one parameter; None (or "") where it said nothing usable.

    ``conversion`` is a conversion index the master can apply (one of
    :data:`~pkwbus.protocol.values.types.CONVERSION_FACTORS`); ``low_raw`` and
    ``high_raw`` are the limits as numbers of the parameter's type, unscaled.
    """

    type_code: int | None = None
    array: int | None = None  # number of elements, when the drive says it is an array
    conversion: int | None = None
    unit: str | None = None  # None: the drive gave no unit it can be read by
    name: str = ""
    low_raw: int | float | None = None
    high_raw: int | float | None = None
    read_only: bool | None = None

    @property
    def vtype(self) -> ValueType | None:
        if self.type_code is None:
            return None
        return DATA_TYPES.get(self.type_code, ("", None))[1]

    @property
    def type_name(self) -> str:
        if self.type_code is None:
            return ""
        return DATA_TYPES.get(self.type_code, (f"type {self.type_code}", None))[0]

    @property
    def scaling(self) -> Scaling | None:
        return None if self.conversion is None else Scaling(CONVERSION_FACTORS[self.conversion])

    @property
    def empty(self) -> bool:
        return self == _NOTHING

    def limit(self, number: int | float | None) -> float | None:
        """A limit in engineering units (scaled), None where it cannot be read."""
        if number is None:
            return None
        scaling = self.scaling or UNSCALED
        return float(number * scaling.factor)

    @property
    def minimum(self) -> float | None:
        return self.limit(self.low_raw)

    @property
    def maximum(self) -> float | None:
        return self.limit(self.high_raw)


_NOTHING: Final = DriveDescription()


def read_elements(
    form: DescriptionForm, found: Mapping[int, pkw.DescriptionResponse | None]
) -> DriveDescription:
    """The description the elements in ``found`` give (None: the drive had none)."""
    type_code = array = conversion = None
    low: int | float | None = None
    high: int | float | None = None
    unit: str | None = None
    read_only: bool | None = None
    not_scaled = False
    if (kind := found.get(DATA_TYPE)) is not None:
        type_code = kind.raw & 0xFF
        if form is DescriptionForm.PROFIDRIVE:
            ident = kind.raw & 0xFFFF
            read_only = bool(ident & _ID_READ_ONLY)
            not_scaled = bool(ident & _ID_NOT_SCALED)
            is_array = bool(ident & _ID_ARRAY)
        else:
            is_array = True  # FC: element 2 says whether it is one
    else:
        is_array = form is DescriptionForm.DANFOSS_FC
    if (size := found.get(SIZE)) is not None and is_array and (size.raw & 0xFFFF) > 0:
        kind_type = DATA_TYPES.get(type_code or 0, ("", None))[1]
        if kind_type is not ValueType.TEXT:  # a text's element 2 is its length
            array = size.raw & 0xFFFF
    if (attribute := found.get(SCALING)) is not None and not not_scaled:
        word = attribute.raw & 0xFFFF
        if form is DescriptionForm.DANFOSS_FC:
            index, size_index = word >> 8, word & 0xFF
        else:
            size_index, index = word >> 8, word & 0xFF
        index = index - 0x100 if index & 0x80 else index
        if index in CONVERSION_FACTORS:
            conversion = index
            if form is DescriptionForm.PROFIDRIVE:
                unit = BASE_UNITS.get(size_index)
            elif size_index == 17 and index == _FC_CELSIUS:
                unit = "°C"
            else:
                unit = FC_BASE_UNITS.get(size_index)
    name = ""
    if (named := found.get(NAME)) is not None:
        name = decode_text(named.data or named.raw.to_bytes(4, "big")).strip("\x00 ")
    vtype = DATA_TYPES.get(type_code, ("", None))[1] if type_code is not None else None
    if (element := found.get(LIMITS[0])) is not None:
        low = _limit(element, vtype, form)
    if (element := found.get(LIMITS[1])) is not None:
        high = _limit(element, vtype, form)
    return DriveDescription(type_code, array, conversion, unit, name, low, high, read_only)


def _limit(
    element: pkw.DescriptionResponse, vtype: ValueType | None, form: DescriptionForm
) -> int | float | None:
    """A limit as a number of the parameter's type: a word type's from the low word (FC:
    "the data type of Lower limit is the same as for the parameter itself", in PWE low of
    the 4-word block), as its sign says; a double word as a float for f32, else signed
    (PROFIdrive: "32 bit signed") or as the type's sign says (FC); None for a text, an
    unknown type or a number outside the type."""
    if vtype is None or vtype is ValueType.TEXT:
        return None
    raw, signed = element.raw, vtype in (ValueType.I16, ValueType.I32)
    if vtype is ValueType.F32:
        if element.width is pkw.Width.WORD:
            return None
        number: float = struct.unpack(">f", (raw & 0xFFFFFFFF).to_bytes(4, "big"))[0]
        return number if number == number else None
    word = vtype.width is pkw.Width.WORD and form is DescriptionForm.DANFOSS_FC
    bits = 16 if word or element.width is pkw.Width.WORD else 32
    raw &= (1 << bits) - 1
    if (signed or (bits == 32 and form is DescriptionForm.PROFIDRIVE)) and raw >> (bits - 1):
        raw -= 1 << bits
    low, high = vtype.bounds
    return raw if low <= raw <= high else None


@dataclass(frozen=True, slots=True)
class Characteristics:
    """FC description element 21, "Additional characteristics" (FC 300 Design Guide
    MG.33.B3.22): what a master may do with a parameter over the bus."""

    raw: int

    @property
    def no_bus_access(self) -> bool:
        return bool(self.raw >> 9 & 1)

    @property
    def bus_read_only(self) -> bool:
        """Bits 10 (standard bus) and 11 (PROFIBUS): "can only be read over the bus"."""
        return bool(self.raw >> 10 & 0b11)

    @property
    def not_while_running(self) -> bool:
        """Bit 13: "the parameter cannot be changed while running"."""
        return bool(self.raw >> 13 & 1)

    @property
    def power_unit_dependent(self) -> bool:
        """Bit 15, or a special default or limit (bits 0-2): the values depend on the
        power unit."""
        return bool(self.raw >> 15 & 1 or self.raw & 0b111)

    @classmethod
    def of(cls, element: pkw.DescriptionResponse) -> Characteristics:
        return cls(element.raw & 0xFFFF)


def changed_from_factory(identifier: pkw.DescriptionResponse) -> bool:
    """PROFIdrive description element 1, bit 12: the value differs from the factory setting."""
    return bool(identifier.raw & _ID_CHANGED)


def factory_raw(element: pkw.DescriptionResponse, vtype: ValueType | None) -> int | float | None:
    """FC element 20, the factory setting, as a number of the parameter's type (the low
    word of a word type, as for the limits); None for a text, an unknown type or a number
    outside the type."""
    return _limit(element, vtype, DescriptionForm.DANFOSS_FC)
