"""The alarm words and fault numbers a drive's catalog explains, polled by default where
the configuration does not poll them (``alarms: auto``): slowly, and counted in
``check-config``'s estimate like any poll."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pkwbus.catalog.alarms import CodeTable, WordTable, alarm_table
from pkwbus.protocol.values import ParameterRef, parse_parameter

if TYPE_CHECKING:
    from pkwbus.service.config.drive import DriveBase
    from pkwbus.service.config.line import LineBase

__all__ = ["ALARM_EVERY", "alarm_polls"]

ALARM_EVERY = 30.0  # seconds: the alarm words polled by default, slowly


def alarm_polls(line: LineBase[Any], drive: DriveBase, polled: set[int]) -> list[ParameterRef]:
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
        if entry.kind == "status" or not active or not entry.polled or ref.pnu in polled:
            continue
        array = isinstance(entry, CodeTable)  # fault buffers: the first entry
        wanted.append(ParameterRef(ref.pnu, 0 if array else None, ref.name))
    return wanted
