"""Jobs: reads, writes and probes, for which drive, how urgent, until when, and their result."""

from __future__ import annotations

import asyncio
import enum
from dataclasses import dataclass, field

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.master.planning.outcomes import Cancelled, JobOutcome, Outcome
from pkwbus.master.planning.transaction import Tally
from pkwbus.master.reading import Reading
from pkwbus.protocol import pkw

__all__ = ["Cancelled", "Job", "JobKind", "JobOutcome", "JobResult", "Priority", "ProbeJob"]


class JobKind(enum.StrEnum):
    READ = "read"
    WRITE = "write"
    PROBE = "probe"


class Priority(enum.IntEnum):
    """Lower goes first: writes, then on-demand reads, then polls, then background jobs
    (the reading of a drive's own log: never ahead of a poll that is due)."""

    WRITE = 0
    READ = 1
    POLL = 2
    BACKGROUND = 3


@dataclass(frozen=True, slots=True)
class JobResult:
    """What a job came to: its outcome, and the value when it carried one.

    ``previous``: for a job that ran, the parameter's latest confirmed value just
    before its answer (a write's old value), None when none was known.
    """

    outcome: Outcome
    raw: int | None = None
    value: Value | None = None
    tally: Tally | None = None
    previous: Reading | None = None


@dataclass(eq=False)
class Job:
    """A PKW job queued on a line for one drive."""

    drive: str
    request: pkw.PkwRequest
    kind: JobKind
    priority: Priority
    deadline: float
    fmt: ParameterDescription = field(default_factory=ParameterDescription)
    future: asyncio.Future[JobResult] | None = None
    parameter: str = ""
    index: int = 0

    def resolve(self, result: JobResult) -> None:
        if self.future is not None and not self.future.done():
            self.future.set_result(result)


@dataclass(eq=False)
class ProbeJob:
    """Whether a drive answers at all: its carrier's probe (the shortest telegram it
    answers, the one a down drive is probed with), repeated as a read is; a scan's and a
    configuration check's question. It ends :class:`Heard` (the answer's status word in
    its tally) or without an answer."""

    drive: str
    deadline: float
    future: asyncio.Future[JobResult] | None = None
    kind: JobKind = JobKind.PROBE
    priority: Priority = Priority.READ

    def resolve(self, result: JobResult) -> None:
        if self.future is not None and not self.future.done():
            self.future.set_result(result)
