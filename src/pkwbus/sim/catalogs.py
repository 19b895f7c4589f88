"""Parameters from a catalog (``pkwbus.catalog``), merged over the built-in table.

A parameter both know keeps the built-in table's live reading (the drive
model's quantity) but takes the catalog's type, scaling, unit and limits, so
that a master decoding with the same catalog reads the model's value. The
model's units are converted to the catalog's where they differ.
"""

from __future__ import annotations

import dataclasses

from pkwbus.catalog import Catalog, CatalogError, ParameterSpec, load_catalog
from pkwbus.protocol.params import ValueType
from pkwbus.protocol.telegram import Protocol
from pkwbus.sim.table import TABLES, ParamSpec

# (model unit, catalog unit) -> factor. The simulated motor has two pole pairs.
UNIT_FACTORS = {
    ("kW", "W"): 1000.0,
    ("W", "kW"): 0.001,
    ("h", "s"): 3600.0,
    ("kWh", "J"): 3.6e6,
    ("kWh", "Wh"): 1000.0,
    ("Hz", "rpm"): 30.0,
    ("Hz", "1/s"): 0.5,
    ("ms", "s"): 0.001,
}

__all__ = ["CatalogError", "specs_from_catalog"]


def specs_from_catalog(protocol: Protocol, name: str) -> tuple[ParamSpec, ...]:
    catalog: Catalog = load_catalog(name)
    merged = {spec.pnu: spec for spec in TABLES[protocol]}
    for entry in catalog.parameters.values():
        known = merged.get(entry.pnu)
        merged[entry.pnu] = _merge(known, entry) if known is not None else _spec(entry)
    return tuple(merged.values())


def _merge(known: ParamSpec, entry: ParameterSpec) -> ParamSpec:
    """The built-in parameter with the catalog's type, scaling, unit and limits."""
    vtype = ValueType(entry.type) if entry.type else known.vtype
    factor = _unit_factor(known.unit, entry.unit) if known.live is not None else 1.0
    return dataclasses.replace(
        known,
        name=entry.name,
        vtype=vtype,
        conversion=entry.conversion or 0,
        scale=entry.scale,
        unit=entry.unit or known.unit,
        minimum=entry.min if entry.min is not None else _scaled(known.minimum, factor),
        maximum=entry.max if entry.max is not None else _scaled(known.maximum, factor),
        unit_factor=factor,
        initial=_initial(entry, known) if known.live is None else known.initial,
    )


def _unit_factor(model: str, wanted: str) -> float:
    if not model or not wanted or model == wanted:
        return 1.0
    try:
        return UNIT_FACTORS[model, wanted]
    except KeyError:
        raise CatalogError(
            f"the simulated drive gives {model!r}, the catalog wants {wanted!r}: no conversion"
        ) from None


def _scaled(limit: float | None, factor: float) -> float | None:
    return None if limit is None else limit * factor


def _initial(entry: ParameterSpec, known: ParamSpec) -> float | str | tuple[float, ...]:
    if isinstance(known.initial, str) or entry.type == "text":
        return known.initial if isinstance(known.initial, str) else ""
    low, high = entry.min, entry.max
    number = known.initial if isinstance(known.initial, float | int) else 0.0
    if low is not None and number < low:
        return float(low)
    if high is not None and number > high:
        return float(high)
    return known.initial


def _spec(entry: ParameterSpec) -> ParamSpec:
    vtype = ValueType(entry.type) if entry.type else ValueType.U16
    low, high = entry.min, entry.max
    initial: float | str = 0.0
    if vtype is ValueType.TEXT:
        initial = entry.name[:16]
    elif low is not None and low > 0:
        initial = float(low)
    elif high is not None and high < 0:
        initial = float(high)
    return ParamSpec(
        pnu=entry.pnu,
        name=entry.name,
        vtype=vtype,
        conversion=entry.conversion or 0,
        scale=entry.scale,
        unit=entry.unit,
        minimum=low,
        maximum=high,
        writable=entry.writable,
        array=entry.array or 0,
        initial=initial,
    )
