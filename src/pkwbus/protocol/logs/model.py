"""A drive's log as pkwbus reads it: the reads, the entries, the sweep of a whole log."""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

from pkwbus.errors import PkwbusError

__all__ = [
    "MS_PER_DAY",
    "Age",
    "DriveLog",
    "Kind",
    "LogEntry",
    "NoSuchLog",
    "Opaque",
    "Read",
    "Runtime",
    "Sweep",
    "SweepResult",
    "TimeBase",
    "Values",
]

MS_PER_DAY = 86_400_000


class Kind(enum.StrEnum):
    """What a log entry is, as `GET /api/v1/events` names its `kind` (README.md, "HTTP API"):
    a Danfoss alarm-log entry is a trip, a fault."""

    FAULT = "fault"
    ALARM = "alarm"
    WARNING = "warning"


class TimeBase(enum.StrEnum):
    """What a log's entry times count."""

    # the drive's runtime, r2114: SINAMICS since power-up, MICROMASTER 4 its powered time
    RUNTIME = "runtime"
    NONE = "none"  # no time a document explains: when pkwbus first read it is all there is
    DESCRIBED = "described"  # as the drive describes its time parameter (PROFIdrive P948)


@dataclass(frozen=True, slots=True)
class Read:
    """One value to read: a parameter number, its index (0 for a simple parameter), and
    whether its document gives it a sign (the caller decodes the drive's raw value so);
    with ``element``, that element of the parameter's description instead (PKW AK 4, data
    record 47's attribute 0x20: element 1 its identifier, which holds its data type)."""

    pnu: int
    index: int = 0
    signed: bool = False
    element: int = 0


@dataclass(frozen=True, slots=True, order=True)
class Runtime:
    """A time in the drive's runtime base: milliseconds since its control unit was
    powered up (SINAMICS: days x 86,400,000 + ms), or of its powered time over all
    power-ups (MICROMASTER 4: seconds x 1000)."""

    ms: int

    @classmethod
    def of(cls, days: int, ms: int) -> Runtime:
        return cls(days * MS_PER_DAY + ms)

    @classmethod
    def read(cls, days: int | None, ms: int | None) -> Runtime | None:
        """The runtime of two values read (None where the drive refused either)."""
        return cls.of(days, ms) if days is not None and ms is not None else None

    def __str__(self) -> str:
        days, rest = divmod(self.ms, MS_PER_DAY)
        seconds, ms = divmod(rest, 1000)
        return (
            f"{days} d {seconds // 3600:02d}:{seconds // 60 % 60:02d}:{seconds % 60:02d}.{ms:03d}"
        )


@dataclass(frozen=True, slots=True)
class Opaque:
    """A drive's time of an entry that no document explains (its unit and its reference
    are not known): part of the entry's identity, never read as a time."""

    raw: int

    def __str__(self) -> str:
        return str(self.raw)


@dataclass(frozen=True, slots=True)
class Age:
    """An entry's time as its age: whole ``seconds`` before the drive answered ``read``,
    the read that gave them (``top``: the most its number holds; an age there may have
    stopped counting). An age grows with every read, so it never tells entries apart: the
    caller places the entry on its own clock, when ``read`` was answered, and knows it
    again by where it placed it."""

    seconds: int
    read: Read
    top: int

    def __str__(self) -> str:
        return f"{self.seconds} s before it was read"


@dataclass(frozen=True, slots=True)
class LogEntry:
    """One entry of a drive's log, by its content: what it is, its code (the drive's fault
    or alarm number), its value (None where the log keeps none), and its drive time."""

    kind: Kind
    code: int
    value: int | None
    drive_time: Runtime | Opaque | Age | None


@dataclass(frozen=True, slots=True)
class SweepResult:
    """A whole log read: its entries, newest first, and the drive's runtime when it was
    read (None where the log has no runtime base). ``places``: where each entry stood in
    the log (its index), for a log whose next sweep reads only what came since (empty
    where the log does not need it); never what tells entries apart."""

    entries: tuple[LogEntry, ...]
    runtime: Runtime | None
    places: tuple[int, ...] = ()


Values = Mapping[Read, int | None]  # what a round read; None: the drive refused that one


class NoSuchLog(PkwbusError):
    """The drive refuses what a sweep must know of its log (the buffer's shape): it keeps
    no such log, and the log is not watched."""


class Sweep(Protocol):
    """The reading of one whole log, in rounds, each decided by what the earlier said."""

    def next(self) -> tuple[Read, ...]:
        """The reads of the next round (empty: the sweep is over)."""
        ...

    def feed(self, values: Values) -> None:
        """What the round read (:class:`NoSuchLog` where it says the drive keeps no such
        log)."""
        ...

    def result(self) -> SweepResult | None:
        """The log as read; None when it changed while it was read (sweep again) or
        cannot be read (its entries refused)."""
        ...


class DriveLog(Protocol):
    """One kind of log: its name, its time base, what is watched, and how it is swept."""

    @property
    def name(self) -> str: ...

    @property
    def time_base(self) -> TimeBase: ...

    @property
    def kinds(self) -> tuple[Kind, ...]:
        """The kinds of entry the log holds."""
        ...

    @property
    def runtime(self) -> tuple[Read, ...]:
        """What gives the drive's runtime now (empty: its entries have no runtime base)."""
        ...

    def watch(self) -> tuple[Read, ...]:
        """What is read every ``events_every``: the change counter, or the newest entry."""
        ...

    def sweep(self, previous: SweepResult | None = None) -> Sweep:
        """A new sweep of the whole log; ``previous``: what the last one found, where the
        log's document lets a sweep skip what was already read (None: read it all)."""
        ...
