"""A line opened for a command: the one line runner, the drives asked, no polls.

The command line's ``read``, ``write``, ``describe`` and ``scan`` and the
configuration check's ``--probe`` run so, on every bus: the port opened by
the runner (the wire's start included: a DP line listens for other masters
first), the drives given and no polls, each job or probe submitted and
waited for, then the runner stopped (a DP line clears its slaves before the
port closes). What is sent, repeated and given up is the planner's, as on the
service's lines: a session has no retry loop of its own. A watcher of the
line's events may end the session early (:meth:`LineSession.end`): a DP slave
owned by another master, one that does not answer, another master heard.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
from collections.abc import Sequence
from typing import Any, TypeVar

from pkwbus.catalog.description import ParameterDescription
from pkwbus.errors import PkwbusError
from pkwbus.link import PortError
from pkwbus.master.events import Observer
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.jobs import Job, JobKind, JobResult, Priority, ProbeJob
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.runner import LineRefused, LineRunner, Port, Wire
from pkwbus.protocol import pkw
from pkwbus.protocol.values.types import ValueType

__all__ = ["EndKind", "LineSession", "SessionEnded"]

T = TypeVar("T")
Request = TypeVar("Request")
Answer = TypeVar("Answer")

# A command asks and reports: a drive that does not answer is not taken down and probed
# at back-off behind its back (each probe is the command's own).
_ASKED_ONLY = HealthPolicy(from_answers=False)


class EndKind(enum.StrEnum):
    """Why a session ended before its job did (the command's error kind)."""

    LOCKED = "locked"  # the DP slave belongs to another master
    TIMEOUT = "timeout"  # the slave does not answer at all
    LINE_ERROR = "line_error"  # the line was given up (another master heard on it)


class SessionEnded(PkwbusError):
    """The session cannot go on (``kind``; the reason in words)."""

    def __init__(self, kind: EndKind, reason: str) -> None:
        super().__init__(reason)
        self.kind = kind


class LineSession:
    """One line for a command, driven by the one runner: jobs and probes one after the other."""

    def __init__(
        self,
        port: Port[Request, Answer],
        wire: Wire[Request, Answer],
        drives: Sequence[DriveSpec],
        *,
        retries: int,
        observers: Sequence[Observer] = (),
    ) -> None:
        # The session asks nothing of the requests and answers: the runner's own business.
        self.runner: LineRunner[Any, Any] = LineRunner(
            "command line", port, wire, drives, retries=retries, observers=observers,
            policy=_ASKED_ONLY, log_port=False,  # the command says it (PortError)
        )  # fmt: skip
        # Set (to SessionEnded) by the watcher; a job waits for it beside its own result.
        self.ended: asyncio.Future[None] | None = None
        self._task: asyncio.Task[None] | None = None

    async def __aenter__(self) -> LineSession:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def end(self, kind: EndKind, reason: str) -> None:
        """What the session's watcher says: it cannot go on (the job waiting ends with it)."""
        if self.ended is not None and not self.ended.done():
            self.ended.set_exception(SessionEnded(kind, reason))

    async def open(self) -> None:
        """Open the port and start the runner; PortError when the port cannot be opened,
        :class:`SessionEnded` when the wire gave it up while starting."""
        loop = asyncio.get_running_loop()
        self.ended = loop.create_future()
        link = self.runner.link
        with contextlib.suppress(LineRefused):  # given up: told to the watcher as a loss
            await self.runner.open()
        if self.ended.done():
            self.ended.result()  # raises what ended it
        if not link.is_open:
            raise PortError(link.reconnect.last_error or f"{link.settings.url} was given up")
        self._task = asyncio.create_task(self.runner.run(), name="line command line")
        await asyncio.sleep(0)  # the runner takes the line as up before any job comes

    async def job(
        self,
        drive: str,
        request: pkw.PkwRequest,
        deadline: float,
        vtype: ValueType | None = None,
    ) -> JobResult:
        """One read or write of ``drive`` (``vtype``: the value type it is known by);
        :class:`SessionEnded` when the watcher ended the session first."""
        loop = asyncio.get_running_loop()
        write = request.is_write or bool(request.text)
        kind = JobKind.WRITE if write else JobKind.READ
        priority = Priority.WRITE if write else Priority.READ
        fmt = ParameterDescription(vtype=vtype)
        return await self._wait(
            Job(drive, request, kind, priority, deadline, fmt, loop.create_future())
        )

    async def probe(self, drive: str, deadline: float) -> JobResult:
        """Whether ``drive`` answers its probe (:class:`~pkwbus.master.planning.outcomes.Heard`,
        its status word in the tally)."""
        loop = asyncio.get_running_loop()
        return await self._wait(ProbeJob(drive, deadline, loop.create_future()))

    async def _wait(self, job: Job | ProbeJob) -> JobResult:
        assert job.future is not None
        self.runner.submit(job)
        return await self.until(job.future)

    async def until(self, done: asyncio.Future[T]) -> T:
        """What ``done`` comes to (a job's result, or what an observer of the line's events
        waits for); :class:`SessionEnded` when the watcher ended the session first."""
        ended = self.ended
        assert ended is not None  # opened
        waits: list[asyncio.Future[Any]] = [done, ended]
        await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        if done.done():
            return done.result()
        raise ended.exception() or SessionEnded(EndKind.LINE_ERROR, "the session ended")

    async def close(self) -> None:
        ended = self.ended
        if ended is not None and ended.done():
            ended.exception()  # told (or to be told) by the caller: not left unretrieved
        self.runner.stop()
        task = self._task
        if task is not None:
            with contextlib.suppress(Exception):
                await task
        elif self.runner.link.is_open:
            await self.runner.close()
