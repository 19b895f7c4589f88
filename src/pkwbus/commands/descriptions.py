"""What a drive's description elements (PKW request AK 4) say, in words and numbers, and
the report `pkwbus describe` prints of them (FC, USS and PROFIBUS alike).

The elements are read in the form of the drive's dialect
(:func:`pkwbus.protocol.pkw.descriptions.form_of`,
:func:`~pkwbus.protocol.pkw.descriptions.read_elements`):
the Danfoss FC form (FC protocol) or the PROFIdrive one (USS, PROFIBUS).

Raises :class:`~pkwbus.commands.common.CommandError` when the drive describes none of
the elements, or the dialect has no description request.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from fractions import Fraction
from typing import Any

from pkwbus.commands.common import CommandError, Exit, emit_json
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import (
    DATA_TYPE,
    LIMITS,
    NAME,
    SCALING,
    SIZE,
    DescriptionForm,
    DriveDescription,
    form_of,
    read_elements,
)
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.values import ParameterRef

__all__ = ["ELEMENTS", "describe", "report"]

ELEMENTS = (DATA_TYPE, SIZE, SCALING, NAME, *LIMITS)  # 1, 2, 4, 6, 7, 8

Found = Mapping[int, pkw.DescriptionResponse | None]


def describe(found: Found, dialect: Dialect) -> dict[str, Any]:
    """What the elements say, in words and numbers: data type, array elements,
    conversion and unit index, unit, read-only, name, limits (each when known)."""
    form = _form(dialect)
    said = read_elements(form, found)
    out: dict[str, Any] = {}
    if said.type_code is not None:
        out["data_type"] = {"code": said.type_code, "name": said.type_name}
    if said.array is not None:
        out["array_elements"] = said.array
    attribute = found.get(SCALING)
    if said.conversion is not None and attribute is not None:
        out["conversion_index"] = said.conversion
        out["unit_index"] = _unit_index(form, attribute.raw)
    if said.unit is not None:
        out["unit"] = said.unit
    if said.read_only is not None:
        out["read_only"] = said.read_only
    if said.name:
        out["name"] = said.name
    for key, raw in (("min", said.low_raw), ("max", said.high_raw)):
        if raw is not None:
            out[key] = _engineering(raw, said)
    return out


def report(args: argparse.Namespace, ref: ParameterRef, found: Found, dialect: Dialect) -> int:
    """Print what the drive said of ``ref`` (its description elements); FC/USS and DP alike."""
    if all(v is None for v in found.values()):
        raise CommandError(
            f"{ref}: the drive describes none of its elements", Exit.REJECTED, kind="rejected"
        )
    info = {"parameter": ref.name, "pnu": ref.pnu, **describe(found, dialect)}
    if args.json:
        emit_json(info)
        return Exit.OK
    print(f"{ref.name}: {info.get('name', '(no name)')}")
    if "data_type" in info:
        print(f"  data type: {info['data_type']['name']} ({info['data_type']['code']})")
    for key in ("array_elements", "conversion_index", "unit_index", "unit", "read_only"):
        if key in info:
            print(f"  {key.replace('_', ' ')}: {_shown(info[key])}")
    for key in ("min", "max"):
        if key in info:
            print(f"  {key}: {info[key]}")
    return Exit.OK


def _form(dialect: Dialect) -> DescriptionForm:
    form = form_of(dialect)
    if form is None:
        raise CommandError(
            f"the {dialect.name} dialect has no description request (AK 4)", Exit.BAD_INPUT
        )
    return form


def _unit_index(form: DescriptionForm, raw: int) -> int:
    """The unit (size) index in element 4: the FC form's low byte (Danfoss FC 300 Design
    Guide, "Read parameter description"), the PROFIdrive variable attribute's first byte
    (Danfoss VLT PROFIBUS manual MG.33.C4.02, section 5 "Parameter description")."""
    word = raw & 0xFFFF
    return word & 0xFF if form is DescriptionForm.DANFOSS_FC else word >> 8


def _engineering(raw: int | float, said: DriveDescription) -> int | float:
    """A limit scaled by the conversion index the drive gave (none: as it is); a whole
    number stays an int."""
    factor = said.scaling.factor if said.scaling is not None else Fraction(1)
    if isinstance(raw, float):
        return raw * float(factor) if factor != 1 else raw
    scaled = raw * factor
    return int(scaled) if scaled.denominator == 1 else float(scaled)


def _shown(value: Any) -> str:
    if value is True or value is False:
        return "yes" if value else "no"
    return str(value) if value != "" else "(none)"
