"""What a simulated drive says of one of its parameters: its description elements (PKW
request AK 4), in the form of the drive's dialect (:mod:`pkwbus.protocol.pkw.descriptions`).

- **Danfoss FC** (Danfoss FC 300 Design Guide, "Read parameter description"): 1 the
  data type; 2 the number of array elements (0 when not an array); 4 the conversion
  index in the high byte (signed) and the unit index in the low byte; 6 the name, a
  text as long as it is (the guide's example answers "LANGUAGE" in 8 bytes); 7 and 8
  the limits as raw values of the parameter's type; 20 the default (factory) value:
  "The data type of Default value is the same as for the parameter itself" (FC 300
  Design Guide MG.33.B3.22, "Default value (index 20)"); here the spec's initial value
  (an array's first element) in the encoding and width of the limits, so neither for a
  text nor for a float; 21 "Additional characteristics" (same guide, "Additional characteristics
  (index 21)"), a word in PWE low: bits 7-8 LCP access (read/write, bit 8, for a
  parameter the drive lets the bus write; read-only, bit 7, for the others, which say
  too "Std Bus Read Only" and "Profibus Read Only", bits 10 and 11), bit 13
  ChangeRunning ("the parameter cannot be changed while running": the spec's
  ``stopped_only``, refused then with fault 17) and bit 15 PowerUnitDependency (the
  spec's ``power_unit``). Bits 0-2 (special default value and limits) and 9 (no bus
  access) are never set: a simulated parameter's default and limits are its spec's,
  and every parameter is on the bus.
- **PROFIdrive** (Danfoss VLT PROFIBUS manual MG.33.C4.02, section 5 "Parameter
  description"; VLT FCD 302 PROFIBUS manual, tables 5.10 and 5.11): 1 the identifier
  (data type, bit 8 "standardisation factor and variable attribute not relevant",
  bit 9 read-only, bit 14 array); 2 the number of array elements, a text's length, else
  0; 4 the variable attribute (first byte the size index, second the conversion
  index); 6 the name in 16 characters; 7 and 8 the limits, "32 bit signed" (a float
  parameter's as the float's bits; a UInt32 limit above 2**31 - 1, which that cannot
  carry, is not available). Identifier bit 12, "Parameter has been changed from factory
  setting" (Danfoss FC 300 PROFIBUS manual MG.33.C2.02, "Identifier ID"): set while a
  stored value (any element of an array, a text) differs from its factory setting, the
  spec's initial value; never for a live value. There is no default-value element:
  20 and 21 are refused as any element the form does not have.

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

__all__ = [
    "NAME_LENGTH",
    "SIZE_INDEXES",
    "TYPE_CODES",
    "Element",
    "characteristics",
    "element",
    "factory_raw",
    "size_index",
]

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
_CHANGED = 1 << 12  # "parameter has been changed from factory setting" (MG.33.C2.02)
_ARRAY = 1 << 14

# FC element 21, "Additional characteristics" (FC 300 Design Guide MG.33.B3.22).
_LCP_READ_ONLY = 0b01 << 7  # bits 8, 7: 01 read-only
_LCP_READ_WRITE = 0b10 << 7  # 10 read/write
_STD_BUS_READ_ONLY = 1 << 10
_PROFIBUS_READ_ONLY = 1 << 11
_CHANGE_RUNNING = 1 << 13  # "cannot be changed while running"
_POWER_UNIT = 1 << 15  # PowerUnitDependency

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
    spec: ParamSpec,
    number: int,
    form: DescriptionForm,
    *,
    text_length: int = 0,
    changed: bool = False,
) -> Element | None:
    """Element ``number`` of ``spec`` in ``form``; None when the drive has no such element.

    ``text_length``: the length of a text parameter's text now (PROFIdrive element 2);
    ``changed``: whether its value now differs from the factory setting (PROFIdrive
    element 1, bit 12).
    """
    if form is DescriptionForm.DANFOSS_FC:
        return _fc(spec, number)
    return _profidrive(spec, number, text_length, changed)


def factory_raw(spec: ParamSpec, index: int = 0) -> int | bytes:
    """The factory setting of element ``index``: its initial value as the raw number on
    the wire (a float's bits), a text's bytes."""
    initial = spec.initial
    if spec.vtype is ValueType.TEXT:
        return str(initial).encode("latin-1")
    number = initial[index] if isinstance(initial, tuple) else initial
    return encode_value(float(number), spec.vtype, spec.scaling)


def characteristics(spec: ParamSpec) -> int:
    """FC element 21, "Additional characteristics", of ``spec``."""
    if not spec.writable or spec.live is not None:
        word = _LCP_READ_ONLY | _STD_BUS_READ_ONLY | _PROFIBUS_READ_ONLY
    else:
        word = _LCP_READ_WRITE
    word |= _CHANGE_RUNNING if spec.stopped_only else 0
    word |= _POWER_UNIT if spec.power_unit else 0
    return word


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
    if number == 20 and spec.vtype not in (ValueType.TEXT, ValueType.F32):
        default = factory_raw(spec)
        assert isinstance(default, int)  # a number: not a text
        return Element(default, width=spec.vtype.width or Width.DWORD)
    if number == 21:
        return Element(characteristics(spec))
    return None


def _profidrive(spec: ParamSpec, number: int, text_length: int, changed: bool) -> Element | None:
    text = spec.vtype is ValueType.TEXT
    if number == 1:
        ident = TYPE_CODES[spec.vtype]
        ident |= _ARRAY if spec.array else 0
        ident |= _READ_ONLY if not spec.writable or spec.live is not None else 0
        ident |= _NOT_SCALED if spec.scale is not None else 0
        ident |= _CHANGED if changed else 0
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
