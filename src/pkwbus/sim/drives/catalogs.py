"""Parameters from a catalog (``pkwbus.catalog``), merged over the built-in table (a
catalog whose drives hold other parameters, ``siemens-mm4``, over its own:
:data:`~pkwbus.sim.drives.table.CATALOG_TABLES`).

A parameter both know keeps the built-in table's live reading (the drive
model's quantity) but takes the catalog's type, scaling, unit and limits, so
that a master decoding with the same catalog reads the model's value. The
model's units are converted to the catalog's where they differ: a live
reading (r0021 in rpm, not the model's Hz) and a stored setting's initial
value and limits alike (p1082 in rpm, 1-20 in W). A setting whose units have
no known conversion keeps its number (it is only a starting value); a live
reading without one is an error. A parameter only the catalog knows starts at a value
within its limits (its factory setting); one of the FC motor data
(:data:`~pkwbus.sim.drives.table.FC_MOTOR_DATA`) changes only while the motor stands
and depends on the power unit, as the table's 1-20.

Raises :class:`~pkwbus.catalog.CatalogError` for a live reading whose unit has no known
conversion.
"""

from __future__ import annotations

import dataclasses

from pkwbus.catalog import Catalog, CatalogError, ParameterSpec, load_catalog
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.values import ValueType
from pkwbus.sim.drives.table import CATALOG_TABLES, FC_MOTOR_DATA, TABLES, ParamSpec

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


def specs_from_catalog(protocol: Bus, name: str) -> tuple[ParamSpec, ...]:
    catalog: Catalog = load_catalog(name)
    base = CATALOG_TABLES.get((protocol, name), TABLES[protocol])
    merged = {spec.pnu: spec for spec in base}
    for entry in catalog.parameters.values():
        known = merged.get(entry.pnu)
        merged[entry.pnu] = _merge(known, entry) if known is not None else _spec(entry, protocol)
    return tuple(merged.values())


def _merge(known: ParamSpec, entry: ParameterSpec) -> ParamSpec:
    """The built-in parameter with the catalog's type, scaling, unit and limits."""
    vtype = ValueType(entry.type) if entry.type else known.vtype
    factor = _unit_factor(known.unit, entry.unit, strict=known.live is not None)
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
        initial=_initial(entry, known, factor) if known.live is None else known.initial,
    )


def _unit_factor(model: str, wanted: str, *, strict: bool) -> float:
    if not model or not wanted or model == wanted:
        return 1.0
    try:
        return UNIT_FACTORS[model, wanted]
    except KeyError:
        if not strict:
            return 1.0
        raise CatalogError(
            f"the simulated drive gives {model!r}, the catalog wants {wanted!r}: no conversion"
        ) from None


def _scaled(limit: float | None, factor: float) -> float | None:
    return None if limit is None else limit * factor


def _initial(
    entry: ParameterSpec, known: ParamSpec, factor: float
) -> float | str | tuple[float, ...]:
    if isinstance(known.initial, str) or entry.type == "text":
        return known.initial if isinstance(known.initial, str) else ""
    if isinstance(known.initial, tuple):
        return tuple(_initial_number(entry, number * factor) for number in known.initial)
    return _initial_number(entry, float(known.initial) * factor)


def _initial_number(entry: ParameterSpec, number: float) -> float:
    low, high = entry.min, entry.max
    if low is not None and number < low:
        return float(low)
    if high is not None and number > high:
        return float(high)
    return number


def _spec(entry: ParameterSpec, protocol: Bus) -> ParamSpec:
    motor_data = protocol is Bus.FC and entry.pnu in FC_MOTOR_DATA
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
        stopped_only=motor_data,
        power_unit=motor_data,
    )
