"""Everything that happens on a line, on one stream: what its planner decided, what its wire
saw on the bus, what its runner saw of the port, and what its snapshot's writer made of them.

The runner publishes them in the order they happened, in batches, to the
observers it was given at its construction (the service's metrics, the
history, a command's watcher): each observer takes the whole stream and
keeps what it needs (:class:`Observer`). The snapshot has one writer
(:class:`~pkwbus.master.snapshot_writer.SnapshotWriter`), which reads the
same stream and adds its own events to it: a job's result, a value that
landed, a description checked against the catalog.
All are small frozen values.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from pkwbus.catalog.precedence import Disagreement
from pkwbus.master.planning.answers import ErrorKind
from pkwbus.master.planning.jobs import JobKind, JobResult
from pkwbus.master.planning.plan import (
    Described,
    Finished,
    HealthChanged,
    Overrun,
    PkwLengthTold,
    StatusWord,
)
from pkwbus.master.planning.plan import Event as PlanEvent
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey
from pkwbus.protocol.profibus.dp.services import Diagnosis
from pkwbus.protocol.profibus.dp.slave_model import RestartReason, SlaveState
from pkwbus.protocol.profibus.fdl import StationType

__all__ = [
    "Described",
    "DescriptionChecked",
    "Event",
    "Exchanged",
    "Finished",
    "HealthChanged",
    "JobDone",
    "LineState",
    "MaintenanceChanged",
    "Observer",
    "Outputs",
    "Overrun",
    "PkwLengthTold",
    "SettingsSeen",
    "SlaveDiagnosed",
    "SlaveRestarted",
    "SlaveSilent",
    "SlaveStateChanged",
    "StationAsked",
    "StationFound",
    "StationsAsked",
    "StatusWord",
    "ValueLanded",
]


# ------------------------------------------------------------------ the wire's


@dataclass(frozen=True, slots=True)
class Exchanged:
    """A request went out to ``drive`` and held the line ``busy`` seconds (its idle time
    before it included); ``answered`` how long its answer took from the request written
    (None: none came, ``error`` says why)."""

    drive: str
    error: ErrorKind | None
    busy: float
    answered: float | None = None


@dataclass(frozen=True, slots=True)
class SlaveStateChanged:
    """A PROFIBUS DP slave's state changed (offline, wait_prm, wait_cfg, data_exchange,
    locked)."""

    drive: str
    state: SlaveState


@dataclass(frozen=True, slots=True)
class SlaveRestarted:
    """A DP slave had to be parametrised again, and why."""

    drive: str
    reason: RestartReason


@dataclass(frozen=True, slots=True)
class SlaveDiagnosed:
    """A DP slave's diagnosis was read: its flags, ident number and owning master."""

    drive: str
    diagnosis: Diagnosis


# ---------------------------------------------------------------- the runner's


@dataclass(frozen=True, slots=True)
class LineState:
    """The line's port opened (``up``) or was lost or given up (``error`` says why)."""

    line: str
    up: bool
    error: str | None = None
    # Given up though open: the line is not to be used (another master runs it).
    refused: bool = False


@dataclass(frozen=True, slots=True)
class MaintenanceChanged:
    """A drive was put in maintenance (``on``: nothing goes out to it, it is neither up nor
    down) or taken out of it; ``reason`` as given."""

    drive: str
    on: bool
    reason: str = ""


@dataclass(frozen=True, slots=True)
class SettingsSeen:
    """What the sweep of a drive's settings found (the service's settings watcher): how
    many differ from their baseline now, and when its last complete sweep ended (wall
    clock; None: none yet). ``changed`` None: its settings are not swept (any more)."""

    drive: str
    changed: int | None
    swept: float | None = None


# -------------------------------------------------------- the snapshot writer's


@dataclass(frozen=True, slots=True)
class JobDone:
    """A job or a poll (a read) is over, decoded: its outcome and value."""

    drive: str
    kind: JobKind
    result: JobResult


@dataclass(frozen=True, slots=True)
class ValueLanded:
    """A polled parameter's new value, as it landed in the snapshot."""

    key: ReadingKey
    reading: Reading


@dataclass(frozen=True, slots=True)
class DescriptionChecked:
    """A parameter's description settled, and the fields on which the drive contradicts
    its catalog (the drive's is used)."""

    event: Described
    found: tuple[Disagreement, ...] = ()


@dataclass(frozen=True, slots=True)
class SlaveSilent:
    """A DP slave out of data exchange left a request unanswered through every repeat: it
    does not answer (it is asked again at back-off). ``detail``: the last try's failure."""

    drive: str
    detail: str


@dataclass(frozen=True, slots=True)
class StationAsked:
    """A live list asks the station at ``address`` (the ``place``-th of ``count``)."""

    address: int
    place: int
    count: int


@dataclass(frozen=True, slots=True)
class StationFound:
    """A station answered a live list's FDL status request: its type, and a slave's
    diagnosis (None: it gave none that could be read)."""

    address: int
    station_type: StationType
    diagnosis: Diagnosis | None = None


@dataclass(frozen=True, slots=True)
class StationsAsked:
    """A live list has asked every station."""


WireEvent = (
    Exchanged | StatusWord | SlaveStateChanged | SlaveRestarted | SlaveDiagnosed | SlaveSilent
    | StationAsked | StationFound | StationsAsked
)  # fmt: skip
Event = (
    PlanEvent | WireEvent | LineState | MaintenanceChanged | SettingsSeen | JobDone
    | ValueLanded | DescriptionChecked
)  # fmt: skip


class Observer(Protocol):
    """One who follows a line's stream of events."""

    def on_events(self, events: Sequence[Event]) -> None: ...


class Outputs:
    """The outputs every line's stream goes to, one list: given to each runner at its
    construction, swapped whole by one call (a reload's new watchers)."""

    __slots__ = ("items",)

    def __init__(self, items: Sequence[Observer] = ()) -> None:
        self.items: tuple[Observer, ...] = tuple(items)

    def swap(self, items: Sequence[Observer]) -> None:
        self.items = tuple(items)

    def on_events(self, events: Sequence[Event]) -> None:
        for output in self.items:
            output.on_events(events)
