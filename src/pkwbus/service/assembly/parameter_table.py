"""Each drive's parameters resolved once, when the service is built: its :class:`ParameterTable`.

The catalog entry of each parameter the configuration names is merged with
the configuration's overrides (type, scaling, unit, limits, name), its
writability taken from the drive's ``writable`` list and its r/p prefix from
the catalog, else the configuration. The running service looks parameters up
in the table and holds no configuration model. Nothing here raises: the
configuration was checked when it was loaded.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import replace
from types import MappingProxyType

from pkwbus.catalog import load_catalog
from pkwbus.catalog.description import (
    OTHER_INDEX,
    ParameterDescription,
    ParameterKey,
    ParameterTable,
)
from pkwbus.catalog.precedence import Layers
from pkwbus.protocol.values import MAX_INDEX, UNSCALED, ParameterRef, ValueType
from pkwbus.service import config as cfg

__all__ = ["explicit_layers", "layers_of", "parameter_table"]

# A configuration field -> the name of what it sets, as catalog.precedence.Layers.given says.
_GIVEN = {"type": "type", "scale": "scaling", "conversion": "scaling", "unit": "unit",
          "min": "min", "max": "max", "name": "name"}  # fmt: skip


def parameter_table(drive: cfg.Drive) -> ParameterTable:
    """The resolved parameters of ``drive``: those it names, and its catalog's."""
    named: dict[int, set[int | None]] = {}
    for _, ref in drive.refs():
        named.setdefault(ref.pnu, {None}).add(ref.index)
    configured: dict[ParameterKey, ParameterDescription] = {}
    for pnu, indexes in named.items():
        prefix = drive.prefix_of(pnu)
        for index in indexes:
            configured[(pnu, index)] = _resolve(drive, pnu, index, prefix)
        # Any index the configuration does not name takes only the overrides without index.
        other = next((i for i in range(MAX_INDEX + 1) if i not in indexes), None)
        if other is not None:
            found = _resolve(drive, pnu, other, prefix)
            if found != configured[(pnu, None)]:
                configured[(pnu, OTHER_INDEX)] = found
    catalog = _catalog(drive.catalog) if drive.catalog is not None else MappingProxyType({})
    return ParameterTable(drive.pkw_dialect.danfoss_numbers, MappingProxyType(configured), catalog)


def _resolve(drive: cfg.Drive, pnu: int, index: int | None, prefix: str) -> ParameterDescription:
    ref = drive.canonical(ParameterRef(pnu, index, str(pnu)))
    found = ParameterDescription.from_spec(drive.spec(ref))
    return replace(found, writable=drive.may_write(ref), prefix=prefix)


@functools.cache
def _catalog(name: str) -> Mapping[int, ParameterDescription]:
    """A catalog's entries as descriptions, shared by its drives; the service writes none
    that a drive's ``writable`` list does not name."""
    return MappingProxyType(
        {
            pnu: replace(ParameterDescription.from_spec(spec), writable=False)
            for pnu, spec in load_catalog(name).parameters.items()
        }
    )


def layers_of(drive: cfg.Drive, table: ParameterTable, ref: ParameterRef) -> Layers:
    """What the configuration sets explicitly of ``ref`` (with its index) and its catalog
    entry: where the drive's own description goes in between."""
    merged = table.describe(ref)
    overrides = drive.overrides_for(ref)
    given = frozenset(_GIVEN[key] for key in overrides.changes())
    config = ParameterDescription(
        name=overrides.name or "",
        vtype=ValueType(overrides.type) if overrides.type is not None else None,
        scaling=overrides.scaling or UNSCALED,
        unit=overrides.unit or "",
        minimum=overrides.min,
        maximum=overrides.max,
    )
    return Layers(merged, config, given, table.catalog.get(ref.pnu))


def explicit_layers(drive: cfg.Drive, table: ParameterTable) -> dict[ParameterKey, Layers]:
    """The layers of every parameter the configuration names, keyed as ``table.configured``
    (an index it does not name under :data:`OTHER_INDEX`): what API reads and writes
    resolve a drive's description against."""
    found: dict[ParameterKey, Layers] = {}
    for pnu, index in table.configured:
        if index == OTHER_INDEX:
            named = {i for p, i in table.configured if p == pnu}
            index_of = next((i for i in range(MAX_INDEX + 1) if i not in named), None)
            if index_of is None:
                continue
            ref = ParameterRef(pnu, index_of, str(pnu))
        else:
            ref = ParameterRef(pnu, index, str(pnu))
        found[(pnu, index)] = layers_of(drive, table, drive.canonical(ref))
    return found
