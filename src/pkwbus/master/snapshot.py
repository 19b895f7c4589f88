"""The latest known state of every drive, as immutable entries a scrape can copy.

The line's snapshot writer replaces entries; readers take :meth:`Snapshot.copy`, never
touching the bus. A value is only ever one the drive actually sent.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass, field

from pkwbus.catalog.alarms import ActiveAlarm
from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.reading import Reading
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.profibus.dp.slave_model import SlaveState
from pkwbus.protocol.values.types import ValueType

__all__ = [
    "Changes",
    "Decoding",
    "DriveCounts",
    "DriveState",
    "LineTotals",
    "LiveSlave",
    "Maintained",
    "ReadingKey",
    "SettingsShown",
    "Snapshot",
    "ValueKey",
]


@dataclass(frozen=True, slots=True)
class DriveState:
    """``main_actual``: the raw main actual value word (0x4000 = 100 %) that came with
    the status word; None until a drive sent one."""

    up: bool = True
    status_word: int | None = None
    status_timestamp: float | None = None
    main_actual: int | None = None


@dataclass(frozen=True, slots=True)
class Maintained:
    """A drive in maintenance: why, and since when (wall clock, seconds)."""

    reason: str
    since: float


@dataclass(frozen=True, slots=True)
class SettingsShown:
    """A drive's settings as last swept: how many differ from their baseline, and when the
    last complete sweep ended (wall clock; None: none yet)."""

    changed: int
    swept: float | None = None


ReadingKey = tuple[str, str, int]  # drive, parameter as configured, index
ValueKey = tuple[str, int, int]  # drive, PNU, index


@dataclass(slots=True)
class Decoding:
    """How a drive's values are decoded now: each polled (parameter, index) as described
    (``formats``), where each polled parameter's description came from when the drive
    described it (``sources``, catalog.precedence.SOURCES), what the drive described of
    its parameters by PNU (``described``), and the PNUs it is describing (``pending``: no
    value of theirs lands, no API read or write of theirs goes out, until it has)."""

    formats: dict[tuple[str, int], ParameterDescription] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    described: dict[int, DriveDescription] = field(default_factory=dict)
    pending: set[int] = field(default_factory=set)


@dataclass(slots=True)
class DriveCounts:
    """What the status page counts of a drive: the drive's fault answers, its telegram
    errors, and when its latest polled value landed (wall clock; None: none yet)."""

    faults: int = 0
    errors: int = 0
    landed: float | None = None


@dataclass(slots=True)
class LineTotals:
    """A line's busy seconds on the wire and its telegrams, since the start."""

    busy: float = 0.0
    telegrams: int = 0


_epochs = itertools.count()


class Changes:
    """Which drives changed, and in what order: each change of a drive's state takes the
    next number, and :meth:`since` walks back from the newest only as far as a token, so
    that an answer of the drives changed since a token costs what it returns.

    A token is ``EPOCH.NUMBER``; a forgotten drive starts a new epoch, so that a client
    holding an older token is given everything again (and sees the drive gone)."""

    __slots__ = ("_at", "epoch", "number")

    def __init__(self) -> None:
        self.epoch = f"{os.getpid():x}{next(_epochs):x}"
        self.number = 0
        self._at: dict[str, int] = {}  # drive -> number of its latest change, oldest first

    def touch(self, drive: str) -> None:
        self.number += 1
        at = self._at
        at.pop(drive, None)
        at[drive] = self.number

    def forget(self, drive: str) -> None:
        if self._at.pop(drive, None) is not None:
            self.epoch = f"{os.getpid():x}{next(_epochs):x}"

    def number_of(self, drive: str) -> int:
        """The number of the drive's latest change (0: none, or not here)."""
        return self._at.get(drive, 0)

    def token(self) -> str:
        return f"{self.epoch}.{self.number}"

    def since(self, token: str) -> list[str] | None:
        """The drives changed after ``token``, newest first; None when the token is not
        one of this snapshot's epoch (everything is to be sent again)."""
        epoch, _, number = token.partition(".")
        if epoch != self.epoch or not number.isdigit() or int(number) > self.number:
            return None
        after = int(number)
        changed = []
        at = self._at
        for drive in reversed(at):
            if at[drive] <= after:
                break
            changed.append(drive)
        return changed


@dataclass
class Snapshot:
    """The read model: every view (the metrics, the API, the status page) reads it, and
    each line's :class:`~pkwbus.master.snapshot_writer.SnapshotWriter` is its only
    writer, fed by the line's events.

    ``readings``: the polled parameters (metrics, /api/v1/drives). ``latest``: the
    latest value each drive confirmed of any parameter, polled, read or written; a
    write counts once the drive's answer echoes the value it now holds. By drive:
    ``decoding`` (how its values are decoded), ``counts`` (faults, telegram errors);
    by line: ``totals``; ``changes``: which drives changed since a token; ``alarms``: the
    drives' active alarms and warnings (alarms first, oldest first; only drives that show
    one), as their polled alarm words and fault numbers tell them
    (:mod:`pkwbus.master.alarms`); ``settings``: what the sweep of each swept drive's
    settings found."""

    readings: dict[ReadingKey, Reading] = field(default_factory=dict)
    drives: dict[str, DriveState] = field(default_factory=dict)
    lines: dict[str, bool] = field(default_factory=dict)
    latest: dict[ValueKey, Reading] = field(default_factory=dict)
    # The value type each drive named for a parameter in its own answers (a typed format
    # of data record 47: Unsigned32, FloatingPoint), by drive and PNU.
    stated: dict[tuple[str, int], ValueType] = field(default_factory=dict)
    # The PROFIBUS DP slaves as the live list shows them, by drive.
    slaves: dict[str, LiveSlave] = field(default_factory=dict)
    # The drives in maintenance: nothing goes out to them.
    maintenance: dict[str, Maintained] = field(default_factory=dict)
    decoding: dict[str, Decoding] = field(default_factory=dict)
    counts: dict[str, DriveCounts] = field(default_factory=dict)
    totals: dict[str, LineTotals] = field(default_factory=dict)
    changes: Changes = field(default_factory=Changes)
    alarms: dict[str, tuple[ActiveAlarm, ...]] = field(default_factory=dict)
    settings: dict[str, SettingsShown] = field(default_factory=dict)

    def forget(self, drive: str) -> None:
        """Everything of ``drive`` (gone from the configuration)."""
        self.readings = {k: v for k, v in self.readings.items() if k[0] != drive}
        self.latest = {k: v for k, v in self.latest.items() if k[0] != drive}
        self.stated = {k: v for k, v in self.stated.items() if k[0] != drive}
        self.drives.pop(drive, None)
        self.slaves.pop(drive, None)
        self.maintenance.pop(drive, None)
        self.decoding.pop(drive, None)
        self.counts.pop(drive, None)
        self.alarms.pop(drive, None)
        self.settings.pop(drive, None)
        self.changes.forget(drive)

    def copy(self) -> Snapshot:
        """The dicts copied (their entries shared): what a scrape reads between awaits."""
        return Snapshot(
            dict(self.readings), dict(self.drives), dict(self.lines), dict(self.latest),
            dict(self.stated), dict(self.slaves), dict(self.maintenance),
            dict(self.decoding), dict(self.counts), dict(self.totals), self.changes,
            dict(self.alarms), dict(self.settings),
        )  # fmt: skip


@dataclass(frozen=True, slots=True)
class LiveSlave:
    """A DP slave as the live list shows it: its state, and its latest diagnosis (ident
    number, owning master, flags; None until one was read)."""

    line: str
    state: SlaveState = SlaveState.OFFLINE
    ident: int | None = None
    owner: int | None = None
    flags: frozenset[str] = frozenset()
    diagnosed: float | None = None  # wall clock of the latest diagnosis
