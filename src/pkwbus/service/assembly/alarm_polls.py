"""The drives' polled alarm parameters the alarm board watches
(:mod:`pkwbus.service.metrics.alarms`)."""

from __future__ import annotations

from pkwbus.catalog.alarms import alarm_table
from pkwbus.master.snapshot import ReadingKey
from pkwbus.service import config as cfg
from pkwbus.service.metrics.alarms import Watched
from pkwbus.service.runtime import DriveEntry

__all__ = ["alarm_parameters"]


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
