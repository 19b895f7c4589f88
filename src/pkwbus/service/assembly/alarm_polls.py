"""The drives' alarm parameters: polled by default where the configuration does not poll
them, and the polled ones the alarm board watches (:mod:`pkwbus.service.alarms`)."""

from __future__ import annotations

from pkwbus.catalog.alarms import CodeTable, WordTable, alarm_table
from pkwbus.master.snapshot import ReadingKey
from pkwbus.protocol.params import ParameterRef, parse_parameter
from pkwbus.service import config as cfg
from pkwbus.service.metrics.alarms import Watched
from pkwbus.service.runtime import DriveEntry

__all__ = ["ALARM_EVERY", "alarm_parameters", "alarm_polls"]

ALARM_EVERY = 10.0  # seconds: the alarm words polled by default, slowly


def alarm_polls(line: cfg.Line, drive: cfg.Drive, polled: set[int]) -> list[ParameterRef]:
    """The alarm words and current fault numbers the drive's catalog explains that the
    configuration does not poll: polled by default (``alarms: auto``), the first element
    of an array."""
    if (drive.alarms or line.alarms) == "off" or drive.catalog is None:
        return []
    table = alarm_table(drive.catalog)
    if table is None:
        return []
    wanted: list[ParameterRef] = []
    entries: list[WordTable | CodeTable] = [*table.words, *table.codes]
    for entry in entries:
        ref = parse_parameter(entry.parameter)
        active = not isinstance(entry, CodeTable) or entry.active
        if entry.kind == "status" or not active or ref.pnu in polled:
            continue
        array = isinstance(entry, CodeTable)  # fault buffers: the first entry
        wanted.append(ParameterRef(ref.pnu, 0 if array else None, ref.name))
    return wanted


def alarm_parameters(config: cfg.Config, entries: list[DriveEntry]) -> dict[ReadingKey, Watched]:
    """The polled parameters whose values tell alarms, by the drive's catalog's alarm table."""
    catalogs = {d.name: d.catalog for _, d in config.drives()}
    watched: dict[ReadingKey, Watched] = {}
    for entry in entries:
        name = catalogs.get(entry.name)
        table = alarm_table(name) if name is not None else None
        if table is None:
            continue
        for poll in entry.polls:
            decoder = table.decoder(poll.request.pnu)
            if decoder is not None:
                watched[(entry.name, poll.parameter, poll.index)] = Watched(entry.line, decoder)
    return watched
