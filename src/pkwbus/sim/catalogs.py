"""Parameters from a catalog (``pkwbus.catalog``), merged over the built-in table.

The catalog package is built in parallel; this adapter reads only the
fields its contract names (pnu, type, conversion, unit, min, max, writable)
and keeps the built-in live readings for parameters both know.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable
from typing import Any

from pkwbus.protocol.params import ValueType
from pkwbus.protocol.telegram import Protocol
from pkwbus.sim.table import TABLES, ParamSpec


class CatalogError(ValueError):
    """A catalog that cannot be loaded or read."""


def specs_from_catalog(protocol: Protocol, name: str) -> tuple[ParamSpec, ...]:
    try:
        module = importlib.import_module("pkwbus.catalog")
        entries = module.load_catalog(name)
    except (ImportError, AttributeError) as exc:
        raise CatalogError(f"catalogs are not available in this build ({exc})") from None
    except (OSError, ValueError, KeyError) as exc:
        raise CatalogError(f"catalog {name!r}: {exc}") from None
    merged = {spec.pnu: spec for spec in TABLES[protocol]}
    for entry in _entries(entries):
        spec = _spec(entry)
        known = merged.get(spec.pnu)
        if known is not None and known.live is not None:
            continue  # the model's reading wins over a static default
        merged[spec.pnu] = spec
    return tuple(merged.values())


def _entries(entries: Any) -> Iterable[Any]:
    values = getattr(entries, "values", None)
    return list(values()) if callable(values) else list(entries)


def _spec(entry: Any) -> ParamSpec:
    try:
        pnu = int(getattr(entry, "pnu"))  # noqa: B009
        vtype = ValueType(str(getattr(entry, "type", "u16")))
        low, high = getattr(entry, "min", None), getattr(entry, "max", None)
        return ParamSpec(
            pnu=pnu,
            name=str(getattr(entry, "name", pnu)),
            vtype=vtype,
            conversion=int(getattr(entry, "conversion", 0) or 0),
            unit=str(getattr(entry, "unit", "") or ""),
            minimum=None if low is None else float(low),
            maximum=None if high is None else float(high),
            writable=bool(getattr(entry, "writable", False)),
            initial="" if vtype is ValueType.TEXT else _initial(low, high),
        )
    except (AttributeError, TypeError, ValueError) as exc:
        raise CatalogError(f"catalog entry {entry!r} cannot be simulated: {exc}") from None


def _initial(low: Any, high: Any) -> float:
    """A value inside the limits: 0 when allowed, else the nearer limit."""
    if low is not None and float(low) > 0:
        return float(low)
    if high is not None and float(high) < 0:
        return float(high)
    return 0.0
