"""The latest known state of every drive, as immutable entries a scrape can copy.

The line's snapshot writer replaces entries; readers take :meth:`Snapshot.copy`, never
touching the bus. A value is only ever one the drive actually sent.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pkwbus.catalog.description import Value
from pkwbus.protocol.profibus.dp.slave_model import SlaveState
from pkwbus.protocol.values.types import ValueType

__all__ = [
    "DriveState",
    "LiveSlave",
    "Maintained",
    "Reading",
    "ReadingKey",
    "Snapshot",
    "ValueKey",
]


@dataclass(frozen=True, slots=True)
class Reading:
    value: Value
    raw: int | None
    timestamp: float  # wall clock, seconds


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


ReadingKey = tuple[str, str, int]  # drive, parameter as configured, index
ValueKey = tuple[str, int, int]  # drive, PNU, index


@dataclass
class Snapshot:
    """``readings``: the polled parameters (metrics, /api/v1/drives). ``latest``: the
    latest value each drive confirmed of any parameter, polled, read or written; a
    write counts once the drive's answer echoes the value it now holds."""

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

    def forget(self, drive: str) -> None:
        """Everything of ``drive`` (gone from the configuration)."""
        self.readings = {k: v for k, v in self.readings.items() if k[0] != drive}
        self.latest = {k: v for k, v in self.latest.items() if k[0] != drive}
        self.stated = {k: v for k, v in self.stated.items() if k[0] != drive}
        self.drives.pop(drive, None)
        self.slaves.pop(drive, None)
        self.maintenance.pop(drive, None)

    def copy(self) -> Snapshot:
        return Snapshot(
            dict(self.readings), dict(self.drives), dict(self.lines), dict(self.latest),
            dict(self.stated), dict(self.slaves), dict(self.maintenance),
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
