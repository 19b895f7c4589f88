"""What a simulated drive says of one of its parameters: its description elements (PKW
request AK 4), in the form of the drive's dialect (:mod:`pkwbus.protocol.pkw.descriptions`).

- **Danfoss FC** (Danfoss FC 300 Design Guide, "Read parameter description"): 1 the
  data type; 2 the number of array elements (0 when not an array); 4 the conversion
  index in the high byte (signed) and the unit index in the low byte; 6 the name, a
  text as long as it is (the guide's example answers "LANGUAGE" in 8 bytes); 7 and 8
  the limits as raw values of the parameter's type.
- **PROFIdrive** (Danfoss VLT PROFIBUS manual MG.33.C4.02, section 5 "Parameter
  description"; VLT FCD 302 PROFIBUS manual, tables 5.10 and 5.11): 1 the identifier
  (data type, bit 8 "standardisation factor and variable attribute not relevant",
  bit 9 read-only, bit 14 array); 2 the number of array elements, a text's length, else
  0; 4 the variable attribute (first byte the size index, second the conversion
  index); 6 the name in 16 characters; 7 and 8 the limits, "32 bit signed" (a float
  parameter's as the float's bits; a UInt32 limit above 2**31 - 1, which that cannot
  carry, is not available).

The unit index (size index) is the one of the spec's unit in
:data:`~pkwbus.protocol.pkw.descriptions.BASE_UNITS`: a simulated value scaled by its
conversion index is in the spec's unit, so that unit is the base unit the index names.
A unit not in that table ("kW", "h", "rpm") is sent as 0, no dimension: the drive
never claims a base unit its scaled value is not in. The FC 300 Design Guide's unit
table differs from that one (MG.33.C4.02, 6.4.3) in two rows: energy (8) is J at
conversion index 0, temperature (17) K at 0 and degrees Celsius only at 100; so in the
FC form "Wh", and "°C" at another conversion index than 100, are sent as 0 too. A spec
scaled by ``scale`` instead of a conversion index has no element 4 (FC) or says so in
bit 8 (PROFIdrive).

Pure: :func:`element` returns None for an element the drive does not have.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.pkw import Width
from pkwbus.protocol.pkw.descriptions import BASE_UNITS, DescriptionForm
from pkwbus.protocol.values import ValueType, encode_value
from pkwbus.sim.drives.table import ParamSpec

__all__ = ["NAME_LENGTH", "SIZE_INDEXES", "TYPE_CODES", "Element", "element", "size_index"]

# Danfoss data type numbers (FC 202 Design Manual, PKW and data types) for description
# element 1; PROFIdrive's identifier carries the same numbers in bits 0-7.
TYPE_CODES: Final = {
    ValueType.I16: 3,
    ValueType.I32: 4,
    ValueType.U16: 6,
    ValueType.U32: 7,
    ValueType.F32: 8,
    ValueType.TEXT: 9,
}

#: Base unit -> size (unit) index; "%" is Ratio (24), the first of the two rows.
SIZE_INDEXES: Final = {unit: index for index, unit in sorted(BASE_UNITS.items(), reverse=True)}

NAME_LENGTH: Final = 16  # PROFIdrive: the name is a visible string of 16 characters

# PROFIdrive identifier bits (MG.33.C4.02 section 5; VLT FCD 302 PROFIBUS manual, table 5.11).
_NOT_SCALED = 1 << 8
_READ_ONLY = 1 << 9
_ARRAY = 1 << 14

_I32_LOW, _I32_HIGH = ValueType.I32.bounds


@dataclass(frozen=True, slots=True)
class Element:
    """One element's answer: ``raw`` as a number, ``data`` a text's bytes (the name)."""

    raw: int
    data: bytes = b""
    width: Width = Width.WORD


def size_index(unit: str) -> int:
    """The size (unit) index of ``unit``; 0 (no dimension) when it is not a base unit."""
    return SIZE_INDEXES.get(unit, 0)


def _fc_unit_index(spec: ParamSpec) -> int:
    """The FC form's unit index: :func:`size_index`, but 0 where the FC 300 Design
    Guide's unit table reads the index as another unit (J for 8; K for 17 unless the
    conversion index is 100, degrees Celsius)."""
    if spec.unit == "Wh" or (spec.unit == "°C" and spec.conversion != 100):
        return 0
    return size_index(spec.unit)


def element(
    spec: ParamSpec, number: int, form: DescriptionForm, *, text_length: int = 0
) -> Element | None:
    """Element ``number`` of ``spec`` in ``form``; None when the drive has no such element.

    ``text_length``: the length of a text parameter's text now (PROFIdrive element 2).
    """
    if form is DescriptionForm.DANFOSS_FC:
        return _fc(spec, number)
    return _profidrive(spec, number, text_length)


def _fc(spec: ParamSpec, number: int) -> Element | None:
    if number == 1:
        return Element(TYPE_CODES[spec.vtype])
    if number == 2:
        return Element(spec.array)
    if number == 4:
        if spec.scale is not None:
            return None
        return Element((spec.conversion & 0xFF) << 8 | _fc_unit_index(spec))
    if number == 6:
        name = spec.name.encode("latin-1", "replace")
        return Element(int.from_bytes(name[:4].ljust(4, b"\0"), "big"), name)
    if number in (7, 8) and spec.vtype not in (ValueType.TEXT, ValueType.F32):
        limit = spec.minimum if number == 7 else spec.maximum
        if limit is None:
            return None
        raw = encode_value(limit, spec.vtype, spec.scaling)
        return Element(raw, width=spec.vtype.width or Width.DWORD)
    return None


def _profidrive(spec: ParamSpec, number: int, text_length: int) -> Element | None:
    text = spec.vtype is ValueType.TEXT
    if number == 1:
        ident = TYPE_CODES[spec.vtype]
        ident |= _ARRAY if spec.array else 0
        ident |= _READ_ONLY if not spec.writable or spec.live is not None else 0
        ident |= _NOT_SCALED if spec.scale is not None else 0
        return Element(ident)
    if number == 2:
        return Element(spec.array or (text_length if text else 0))
    if number == 4:
        if spec.scale is not None:
            return None  # bit 8 of the identifier: not relevant
        return Element(size_index(spec.unit) << 8 | (spec.conversion & 0xFF))
    if number == 6:
        name = spec.name.encode("latin-1", "replace")[:NAME_LENGTH].ljust(NAME_LENGTH, b" ")
        return Element(int.from_bytes(name[:4], "big"), name)
    if number in (7, 8) and not text:
        limit = spec.minimum if number == 7 else spec.maximum
        signed = None if limit is None else _signed32(spec, limit)
        return None if signed is None else Element(signed & 0xFFFFFFFF, width=Width.DWORD)
    return None


def _signed32(spec: ParamSpec, limit: float) -> int | None:
    """A limit as a 32-bit signed number of its raw value (f32: the float's bits); None
    when it is outside what 32 bits signed carry (a u32 above 2**31 - 1)."""
    raw = encode_value(limit, spec.vtype, spec.scaling)
    if spec.vtype is ValueType.F32:
        return int(struct.unpack(">i", raw.to_bytes(4, "big"))[0])
    if spec.vtype is ValueType.I16 and raw & 0x8000:
        return raw - 0x10000
    if spec.vtype is ValueType.I32 and raw & 0x80000000:
        return raw - 0x100000000
    return raw if _I32_LOW <= raw <= _I32_HIGH else None
