"""A configured drive as the master plans it and the service knows it: where it is
reached, what is polled and described of it (:func:`plan_drive`)."""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType

from pkwbus.catalog.description import ParameterDescription, ParameterTable
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.master.planning.plan import DescribeTarget, DriveSpec, PollSpec
from pkwbus.master.target import DriveTarget, RecordAccess
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import NAME, DescriptionForm, elements_to_read, form_of
from pkwbus.protocol.pkw.length import AUTO
from pkwbus.protocol.profidrive.parameters import AXES
from pkwbus.protocol.serial.telegram import Protocol
from pkwbus.protocol.values import ParameterRef
from pkwbus.service import config as cfg
from pkwbus.service.assembly.parameter_table import (
    explicit_layers,
    layers_of,
    parameter_table,
)
from pkwbus.service.config.default_polls import (
    ALARM_EVERY,
    COUNTER_EVERY,
    alarm_polls,
    counter_polls,
    swept_settings,
)
from pkwbus.service.metrics.devices import ParameterInfo
from pkwbus.service.runtime import DriveEntry

__all__ = ["describe_targets", "description_form", "plan_drive", "target_for"]


def target_for(line: cfg.Line, drive: cfg.Drive) -> DriveTarget:
    """Where and how a configured drive is reached."""
    record = None
    if isinstance(drive, cfg.ProfibusDrive) and drive.access == "ds47":
        axis = drive.axis if drive.axis is not None else AXES.get(drive.pkw_dialect.name, 0)
        settings = drive.dp.settings()[0]
        dpv1 = settings.dpv1 if settings is not None else None
        record = RecordAccess(axis, max_data=dpv1.max_data if dpv1 is not None else 240)
    return DriveTarget(
        Protocol(line.protocol),
        drive.address,
        drive.pkw_dialect,
        drive.layout,
        drive.shape,
        line.address_format,
        learn=isinstance(drive, cfg.UssDrive) and drive.pkw_words == AUTO,
        record=record,
    )


def plan_drive(
    line: cfg.Line,
    drive: cfg.Drive,
    entries: list[DriveEntry],
    infos: list[ParameterInfo],
    book: DescriptionBook | None = None,
) -> DriveSpec:
    target = target_for(line, drive)
    table = parameter_table(drive)
    form = description_form(line, drive)
    polls: list[PollSpec] = []
    sources: dict[str, str] = {}

    def add(ref: ParameterRef, every: float, *, layered: bool, only_described: bool = False
            ) -> ParameterRef:  # fmt: skip
        """One poll: labelled by the drive's one name for its parameter ("1613" polls
        16-13), described by the configuration and the catalog (and the drive's own
        description, where it is asked: ``layered``)."""
        ref = table.canonical(ref)
        fmt = table.describe(ref)
        found = layers_of(drive, table, ref)
        polls.append(
            PollSpec(ref.name, ref.index or 0, _read(target, ref, fmt), every, fmt,
                     found if layered else None, described_only=only_described)
        )  # fmt: skip
        info = _info(line, drive, ref, fmt, found.catalog)
        infos.append(info)
        sources[ref.name] = info.source
        return ref

    for entry in drive.poll:
        add(entry.ref, entry.every, layered=form is not None)
    for ref in alarm_polls(line, drive, {p.request.pnu for p in polls}):
        add(ref, ALARM_EVERY, layered=False)
    counters = [
        add(ref, COUNTER_EVERY, layered=form is not None, only_described=not typed)
        for ref, typed in counter_polls(line, drive)
        if typed or form is not None  # one no document types needs the drive's description
    ]
    _, settings = swept_settings(line, drive)  # described with their limits, for a restore
    describe = describe_targets(target, drive, table, counters, settings) if form else ()
    entries.append(
        DriveEntry(
            drive.name,
            line.name,
            target,
            tuple(polls),
            parameters=table,
            layers=explicit_layers(drive, table),
            sources=MappingProxyType(sources),
        )
    )
    return DriveSpec(drive.name, carrier_for(target), tuple(polls), describe, form, book)


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
    short = (target.protocol is Protocol.PROFIBUS and target.record is None) or (
        isinstance(drive, cfg.UssDrive) and drive.pkw_words in (3, 4)
    )
    targets = []
    for pnu, (name, limits) in wanted.items():
        elements = tuple(e for e in elements_to_read(limits=limits) if not (short and e == NAME))
        catalog = table.catalog.get(pnu)
        targets.append(DescribeTarget(pnu, name, elements, catalog, pnu in writable))
    return tuple(targets)


def _read(target: DriveTarget, ref: ParameterRef, fmt: ParameterDescription) -> pkw.PkwRequest:
    return pkw.read_parameter(target.dialect, ref.pnu, ref.index, text=fmt.is_text)


def _info(
    line: cfg.Line,
    drive: cfg.Drive,
    ref: ParameterRef,
    fmt: ParameterDescription,
    catalog: ParameterDescription | None,
) -> ParameterInfo:
    given = drive.overrides_for(ref).changes().keys() & {"type", "scale", "conversion"}
    source = "config" if given else ("catalog" if catalog is not None else "none")
    return ParameterInfo(
        line.name,
        drive.name,
        ref.name,
        ref.index or 0,
        ref.pnu,
        fmt.name,
        fmt.unit,
        fmt.vtype.value if fmt.vtype else "raw",
        source,
    )
