"""A configured drive resolved once, when the service (or a command's probe) is built.

- Its parameters (:func:`parameter_table`): the catalog entry of each parameter the
  configuration names merged with the configuration's overrides (type, scaling, unit,
  limits, name), its writability taken from the drive's ``writable`` list and its r/p
  prefix from the catalog, else the configuration. The running service looks
  parameters up in the table and holds no configuration model.
- How it is reached (:func:`target_for`: bus, address, dialect, telegram shape, data
  record 47) and asked to describe itself (:func:`description_form`,
  :func:`describe_targets`), and an FC/USS line's port (:func:`port_for`).

Nothing here raises: the configuration was checked when it was loaded.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping, Sequence
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
from pkwbus.link import Fence, PortSettings
from pkwbus.link.port import Rs485Mode
from pkwbus.master.planning.plan import DescribeTarget
from pkwbus.master.target import DriveTarget, RecordAccess
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.descriptions import NAME, DescriptionForm, elements_to_read, form_of
from pkwbus.protocol.pkw.length import AUTO
from pkwbus.protocol.profidrive.parameters import AXES
from pkwbus.protocol.values import MAX_INDEX, UNSCALED, ParameterRef, ValueType
from pkwbus.service import config as cfg

__all__ = [
    "describe_targets",
    "description_form",
    "explicit_layers",
    "layers_of",
    "parameter_table",
    "port_for",
    "target_for",
]


# A configuration field -> the name of what it sets, as catalog.precedence.Layers.given says.
_GIVEN = {"type": "type", "scale": "scaling", "conversion": "scaling", "unit": "unit",
          "min": "min", "max": "max", "name": "name"}  # fmt: skip


def parameter_table(drive: cfg.Drive) -> ParameterTable:
    """The resolved parameters of ``drive``: those it names, and its catalog's."""
    named: dict[int, set[int | None]] = {}
    for _, ref in drive.refs():
        named.setdefault(ref.pnu, {None}).add(ref.index)
    catalog = _catalog(drive.catalog) if drive.catalog is not None else MappingProxyType({})
    configured: dict[ParameterKey, ParameterDescription] = {}
    for pnu, indexes in named.items():
        prefix = drive.prefix_of(pnu)
        for index in indexes:
            configured[(pnu, index)] = _resolve(drive, pnu, _told(catalog, pnu, index, indexes),
                                                prefix)  # fmt: skip
        # Any index the configuration does not name takes only the overrides without index.
        other = next((i for i in range(MAX_INDEX + 1) if i not in indexes), None)
        if other is not None:
            found = _resolve(drive, pnu, other, prefix)
            if found != configured[(pnu, None)]:
                configured[(pnu, OTHER_INDEX)] = found
    return ParameterTable(drive.pkw_dialect.danfoss_numbers, MappingProxyType(configured), catalog)


def _told(
    catalog: Mapping[int, ParameterDescription],
    pnu: int,
    index: int | None,
    named: Iterable[int | None],
) -> int | None:
    """The index whose configuration tells of ``(pnu, index)``: index 0 for the parameter
    itself when its catalog does not call it an array and the configuration names element
    0 (the same telegram: index 0 of a parameter that is no array is the parameter itself,
    so the limits given for ``3-41[0]`` hold for a write of ``3-41`` too); else ``index``."""
    if index is None and 0 in named:
        entry = catalog.get(pnu)
        if entry is None or entry.array is None:
            return 0
    return index


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
        named = {i for p, i in table.configured if p == pnu}
        if index == OTHER_INDEX:
            index_of = next((i for i in range(MAX_INDEX + 1) if i not in named), None)
            if index_of is None:
                continue
            ref = ParameterRef(pnu, index_of, str(pnu))
        else:
            ref = ParameterRef(pnu, _told(table.catalog, pnu, index, named), str(pnu))
        found[(pnu, index)] = layers_of(drive, table, drive.canonical(ref))
    return found


def target_for(line: cfg.Line, drive: cfg.Drive) -> DriveTarget:
    """Where and how a configured drive is reached."""
    record = None
    if isinstance(drive, cfg.ProfibusDrive) and drive.access == "ds47":
        axis = drive.axis if drive.axis is not None else AXES.get(drive.pkw_dialect.name, 0)
        settings = drive.dp.settings()[0]
        dpv1 = settings.dpv1 if settings is not None else None
        record = RecordAccess(axis, max_data=dpv1.max_data if dpv1 is not None else 240)
    return DriveTarget(
        Bus(line.protocol),
        drive.address,
        drive.pkw_dialect,
        drive.layout,
        drive.shape,
        line.address_format,
        learn=isinstance(drive, cfg.UssDrive) and drive.pkw_words == AUTO,
        record=record,
    )


def description_form(line: cfg.Line, drive: cfg.Drive) -> DescriptionForm | None:
    """How the drive describes its parameters, when it is asked to (``describe: auto``)."""
    if (drive.describe or line.describe) == "off":
        return None
    return form_of(drive.pkw_dialect)


def describe_targets(
    target: DriveTarget,
    drive: cfg.Drive,
    table: ParameterTable,
    polled: Sequence[ParameterRef] = (),
    settings: Sequence[ParameterRef] = (),
) -> tuple[DescribeTarget, ...]:
    """The polled (``drive.poll`` and ``polled``), writable and swept (``settings``)
    parameters, each once: polled ones for their type, scaling, unit, size and name;
    writable and swept ones also for their limits. The name is not asked where it does
    not fit the PKW block: a PPO's four words, a fixed USS length."""
    wanted: dict[int, tuple[str, bool]] = {}
    for ref in [*(entry.ref for entry in drive.poll), *polled]:
        ref = table.canonical(ref)
        wanted.setdefault(ref.pnu, (ref.name, False))
    for ref in [*drive.writable, *settings]:
        ref = table.canonical(ref)
        wanted[ref.pnu] = (wanted.get(ref.pnu, (ref.name, True))[0], True)
    writable = {table.canonical(ref).pnu for ref in drive.writable}
    # A name of 16 characters fits neither a PPO's four PKW words nor a fixed USS block
    # (data record 47 carries it).
    short = (target.protocol is Bus.PROFIBUS and target.record is None) or (
        isinstance(drive, cfg.UssDrive) and drive.pkw_words in (3, 4)
    )
    targets = []
    for pnu, (name, limits) in wanted.items():
        elements = tuple(e for e in elements_to_read(limits=limits) if not (short and e == NAME))
        catalog = table.catalog.get(pnu)
        targets.append(DescribeTarget(pnu, name, elements, catalog, pnu in writable))
    return tuple(targets)


def port_for(line: cfg.Line, port: str, fence: Fence | None = None) -> TelegramPort:
    """The FC/USS line a configuration describes, on ``port``; ``fence``: its lease's
    (hot standby; None: always open)."""
    settings = PortSettings(
        port,
        baudrate=line.baudrate,
        parity=line.parity,
        stopbits=line.stopbits,
        pause=line.pause,
        echo=line.echo,
        low_latency=line.low_latency,
        rs485=Rs485Mode(**line.rs485.model_dump()) if line.rs485 is not None else None,
    )
    return TelegramPort(
        settings,
        Bus(line.protocol),
        timeout=line.timeout,
        inter_char_timeout=line.inter_char_seconds,
        fence=fence,
    )
