"""The polls a drive gets by default, where the configuration does not poll the parameter:
the alarm words and fault numbers its catalog explains (``alarms: auto``), and the counters
it keeps of its own life (``counters: auto``). Slowly, and counted in ``check-config``'s
estimate like any poll. And what is read besides the polls: the drive's settings, swept
(``settings``)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pkwbus.catalog import load_catalog
from pkwbus.catalog.alarms import CodeTable, WordTable, alarm_table
from pkwbus.protocol.pkw.descriptions import DescriptionForm, form_of
from pkwbus.protocol.values import ParameterRef, parse_parameter

if TYPE_CHECKING:
    from pkwbus.service.config.drive import DriveBase
    from pkwbus.service.config.line import LineBase

__all__ = [
    "ALARM_EVERY",
    "COUNTER_EVERY",
    "alarm_polls",
    "counter_polls",
    "sweep_rate",
    "swept_settings",
]

ALARM_EVERY = 30.0  # seconds: the alarm words polled by default, slowly
COUNTER_EVERY = 60.0  # seconds: the drive's counters polled by default, more slowly still


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


def counter_polls(line: LineBase[Any], drive: DriveBase) -> list[tuple[ParameterRef, bool]]:
    """The counters the drive's catalog marks (``counter: true``) that its ``poll`` list
    does not poll, each element of an array: polled by default (``counters: auto``), with
    whether a vendor document types them (the catalog's ``verified``). One that no document
    types needs the drive's own description (``describe: auto``): without it, it is left
    out."""
    if (drive.counters or line.counters) == "off" or drive.catalog is None:
        return []
    describes = (drive.describe or line.describe) != "off"
    polled = {(entry.ref.pnu, entry.ref.index) for entry in drive.poll}
    wanted: list[tuple[ParameterRef, bool]] = []
    for spec in load_catalog(drive.catalog).parameters.values():
        if not spec.counter or (not spec.verified and not describes):
            continue
        indexes: list[int | None] = list(range(spec.array)) if spec.array else [None]
        for index in indexes:
            if (spec.pnu, index) in polled or (spec.pnu, None) in polled:
                continue
            wanted.append((ParameterRef(spec.pnu, index, str(spec.pnu)), spec.verified))
    return wanted


def swept_settings(line: LineBase[Any], drive: DriveBase) -> tuple[float, list[ParameterRef]]:
    """The sweep of the drive's settings: its interval, and what it reads - the settings
    its catalog marks (``parameters: catalog``; each element of an array) or the listed
    parameters. No parameters when it is ``off``."""
    chosen = drive.settings if drive.settings is not None else line.settings
    if isinstance(chosen, str):  # off
        return 0.0, []
    if chosen.parameters != "catalog":
        return chosen.every, list(chosen.parameters)
    if drive.catalog is None:
        return chosen.every, []
    wanted: list[ParameterRef] = []
    for spec in load_catalog(drive.catalog).parameters.values():
        if spec.is_setting:
            indexes: list[int | None] = list(range(spec.array)) if spec.array else [None]
            wanted.extend(ParameterRef(spec.pnu, i, str(spec.pnu)) for i in indexes)
    return chosen.every, wanted


def sweep_rate(line: LineBase[Any], drive: DriveBase) -> float:
    """The reads per second the sweep of the drive's settings asks for (``settings``): each
    setting once an interval, and a PROFIdrive drive's identifier with it (whether it
    differs from the factory setting; a Danfoss drive's factory value is read once, and
    not counted)."""
    every, refs = swept_settings(line, drive)
    if not refs:
        return 0.0
    described = (drive.describe or line.describe) != "off"
    per = 2 if described and form_of(drive.pkw_dialect) is DescriptionForm.PROFIDRIVE else 1
    return per * len(refs) / every
