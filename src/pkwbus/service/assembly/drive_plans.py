"""A configured drive as the master plans it and the service knows it: where it is
reached, what is polled and described of it (:func:`plan_drive`)."""

from __future__ import annotations

from types import MappingProxyType

from pkwbus.catalog.alarms import AlarmDecoder, alarm_table
from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.alarms import tells_alarms
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.master.planning.plan import DriveSpec, PollSpec
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.values import ParameterRef
from pkwbus.service import config as cfg
from pkwbus.service.config.default_polls import (
    ALARM_EVERY,
    COUNTER_EVERY,
    alarm_polls,
    counter_polls,
    swept_settings,
)
from pkwbus.service.config.resolved import (
    describe_targets,
    description_form,
    explicit_layers,
    layers_of,
    parameter_table,
    target_for,
)
from pkwbus.service.metrics.devices import ParameterInfo
from pkwbus.service.runtime import DriveEntry

__all__ = ["plan_drive"]


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
    words = _alarm_words(drive, polls)
    entries.append(
        DriveEntry(
            drive.name,
            line.name,
            target,
            tuple(polls),
            parameters=table,
            layers=explicit_layers(drive, table),
            sources=MappingProxyType(sources),
            alarm_words=MappingProxyType(words),
        )
    )
    alarms = tuple((p, i, d) for (p, i), d in words.items() if tells_alarms(d))
    return DriveSpec(drive.name, carrier_for(target), tuple(polls), describe, form, book, alarms)


def _alarm_words(drive: cfg.Drive, polls: list[PollSpec]) -> dict[tuple[str, int], AlarmDecoder]:
    """The polled parameters the drive's catalog's alarm table tells in words, by
    parameter and index: alarm words, fault and alarm numbers, status words, logs."""
    table = alarm_table(drive.catalog) if drive.catalog is not None else None
    if table is None:
        return {}
    words = {}
    for poll in polls:
        decoder = table.decoder(poll.request.pnu)
        if decoder is not None:
            words[(poll.parameter, poll.index)] = decoder
    return words


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
