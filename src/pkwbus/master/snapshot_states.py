"""The snapshot's writer, its part for the states a line's events tell: a drive's status
word, the line's port, the DP slaves in the live list, a drive in maintenance, what the
sweep of a drive's settings found. Used by :class:`~pkwbus.master.snapshot_writer.SnapshotWriter`
alone (one writer): each handler takes the snapshot, the line, the event and when it happened.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from pkwbus.master.events import (
    LineState,
    MaintenanceChanged,
    SettingsSeen,
    SlaveDiagnosed,
    SlaveStateChanged,
)
from pkwbus.master.planning.plan import StatusWord
from pkwbus.master.snapshot import DriveState, LiveSlave, Maintained, SettingsShown, Snapshot

__all__ = [
    "HANDLERS",
    "line_state",
    "maintenance",
    "settings_seen",
    "slave_diagnosed",
    "slave_state",
    "status_word",
]

log = logging.getLogger("pkwbus.master.runner")  # what the runner records


def status_word(snapshot: Snapshot, line: str, event: StatusWord, at: float) -> None:
    drives = snapshot.drives
    old = drives.get(event.drive)
    if old is None:
        return  # a drive gone from the line
    drives[event.drive] = DriveState(old.up, event.word, at, event.main_actual)
    if old.status_word != event.word or old.main_actual != event.main_actual:
        snapshot.changes.touch(event.drive)


def line_state(snapshot: Snapshot, line: str, event: LineState, at: float) -> None:
    snapshot.lines[event.line] = event.up


def slave_state(snapshot: Snapshot, line: str, event: SlaveStateChanged, at: float) -> None:
    slaves = snapshot.slaves
    slaves[event.drive] = replace(slaves.get(event.drive, LiveSlave(line)), state=event.state)
    snapshot.changes.touch(event.drive)


def slave_diagnosed(snapshot: Snapshot, line: str, event: SlaveDiagnosed, at: float) -> None:
    slaves, found = snapshot.slaves, event.diagnosis
    slaves[event.drive] = replace(
        slaves.get(event.drive, LiveSlave(line)), ident=found.ident,
        owner=found.master, flags=found.flags, diagnosed=at,
    )  # fmt: skip
    snapshot.changes.touch(event.drive)


def maintenance(snapshot: Snapshot, line: str, event: MaintenanceChanged, at: float) -> None:
    """A drive in maintenance, or out of it: one log line each."""
    drive, ctx = event.drive, {"line": line, "drive": event.drive}
    snapshot.changes.touch(drive)
    if event.on:
        snapshot.maintenance[drive] = Maintained(event.reason, at)
        log.warning("drive %s is in maintenance (%s): nothing goes out to it", drive,
                    event.reason or "no reason given", extra=ctx)  # fmt: skip
    elif snapshot.maintenance.pop(drive, None) is not None:
        log.warning("drive %s is out of maintenance: it is polled again", drive, extra=ctx)


def settings_seen(snapshot: Snapshot, line: str, event: SettingsSeen, at: float) -> None:
    """What the sweep of a drive's settings found (None: not swept any more)."""
    drive, settings = event.drive, snapshot.settings
    if drive not in snapshot.drives:
        return  # a drive gone from the line
    shown = None if event.changed is None else SettingsShown(event.changed, event.swept)
    if settings.get(drive) != shown:
        if shown is None:
            settings.pop(drive, None)
        else:
            settings[drive] = shown
        snapshot.changes.touch(drive)


HANDLERS: dict[type, Callable[[Snapshot, str, Any, float], None]] = {
    StatusWord: status_word,
    LineState: line_state,
    SlaveStateChanged: slave_state,
    SlaveDiagnosed: slave_diagnosed,
    MaintenanceChanged: maintenance,
    SettingsSeen: settings_seen,
}
