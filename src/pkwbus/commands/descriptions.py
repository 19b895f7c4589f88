"""What a drive's description elements (PKW request AK 4) say, in words and numbers, and
the report `pkwbus describe` prints of them (FC, USS and PROFIBUS alike).

Raises :class:`~pkwbus.commands.common.CommandError` when the drive describes none of
the elements.
"""

from __future__ import annotations

import argparse
from typing import Any

from pkwbus.commands.common import CommandError, Exit, emit_json
from pkwbus.protocol import pkw
from pkwbus.protocol.params import (
    CONVERSION_FACTORS,
    DATA_TYPES,
    ParameterRef,
    Scaling,
    ValueType,
    decode_text,
    decode_value,
)

__all__ = ["ELEMENTS", "describe", "report"]

ELEMENTS = (1, 2, 4, 6, 7, 8)


def describe(found: dict[int, pkw.DescriptionResponse | None]) -> dict[str, Any]:
    """What the elements say, in words and numbers."""
    out: dict[str, Any] = {}
    kind = found.get(1)
    vtype: ValueType | None = None
    if kind is not None:
        code = kind.raw & 0xFF
        name, vtype = DATA_TYPES.get(code, (f"type {code}", None))
        out["data_type"] = {"code": code, "name": name}
    if (count := found.get(2)) is not None and count.raw:
        out["array_elements"] = count.raw
    scaling = Scaling()
    if (conv := found.get(4)) is not None:
        index = (conv.raw >> 8) & 0xFF
        index = index - 0x100 if index & 0x80 else index
        out["conversion_index"] = index
        out["unit_index"] = conv.raw & 0xFF
        if index in CONVERSION_FACTORS:
            scaling = Scaling.conversion(index)
    if (named := found.get(6)) is not None:
        text = decode_text(named.data or named.raw.to_bytes(4, "big"))
        if text:
            out["name"] = text
    for element, key in ((7, "min"), (8, "max")):
        limit = found.get(element)
        if limit is not None and vtype is not None and vtype is not ValueType.TEXT:
            out[key] = decode_value(limit.raw, vtype.width or pkw.Width.DWORD, vtype, scaling)
    return out


def report(args: argparse.Namespace, ref: ParameterRef, found: dict[Any, Any]) -> int:
    """Print what the drive said of ``ref`` (its description elements); FC/USS and DP alike."""
    if all(v is None for v in found.values()):
        raise CommandError(
            f"{ref}: the drive describes none of its elements", Exit.REJECTED, kind="rejected"
        )
    info = {"parameter": ref.name, "pnu": ref.pnu, **describe(found)}
    if args.json:
        emit_json(info)
        return Exit.OK
    print(f"{ref.name}: {info.get('name', '(no name)')}")
    if "data_type" in info:
        print(f"  data type: {info['data_type']['name']} ({info['data_type']['code']})")
    for key in ("array_elements", "conversion_index", "unit_index", "min", "max"):
        if key in info:
            print(f"  {key.replace('_', ' ')}: {info[key]}")
    return Exit.OK
