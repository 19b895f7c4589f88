"""Jobs on one drive through the one line runner, for a caller that runs no service.

The command line's ``read``, ``write`` and ``describe`` run their jobs so, on
every bus: the port opened (the wire's start included: a DP line listens for
other masters first), the runner started over the wire with this one drive
and no polls, the jobs submitted one after the other, then the runner stopped
(the wire closes the port, a DP line after Global_Control Clear). A watcher
may end the session early with a reason (a DP slave owned by another master,
one that does not answer, another master heard). :func:`run_job` and
:func:`perform` drive one job by the planner on a line already open (the
commands' scans, the line benchmarks).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Sequence

from pkwbus.catalog.description import ParameterDescription
from pkwbus.link import PortError
from pkwbus.master.carriers import carrier_for
from pkwbus.master.events import Observer
from pkwbus.master.planning.jobs import Job, JobKind, JobResult, Priority
from pkwbus.master.planning.outcomes import Outcome
from pkwbus.master.planning.plan import DriveSpec, Finished, Send
from pkwbus.master.planning.planner import Planner
from pkwbus.master.runner import LineRefused, LineRunner, Wire
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.line import Line
from pkwbus.protocol import pkw
from pkwbus.protocol.values.types import ValueType

__all__ = ["JobSession", "SessionEnded", "perform", "run_job"]


class SessionEnded(Exception):
    """The session cannot go on (``kind``: the command's error kind, the reason in words)."""

    def __init__(self, kind: str, reason: str) -> None:
        super().__init__(reason)
        self.kind = kind


class JobSession:
    """One drive's line, driven by the one runner, for jobs one after the other."""

    def __init__(
        self, wire: Wire, spec: DriveSpec, *, retries: int, observers: Sequence[Observer] = ()
    ) -> None:
        self.wire = wire
        self.drive = spec.name
        self.runner = LineRunner("command line", wire, [spec], retries=retries, observers=observers)
        # Set (to SessionEnded) by the watcher; a job waits for it beside its own result.
        self.ended: asyncio.Future[JobResult] | None = None
        self._task: asyncio.Task[None] | None = None

    def end(self, kind: str, reason: str) -> None:
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
        self, request: pkw.PkwRequest, deadline: float, vtype: ValueType | None = None
    ) -> JobResult:
        """One job (``vtype``: the value type it is known by); :class:`SessionEnded` when
        the watcher ended the session first."""
        ended = self.ended
        assert ended is not None  # opened
        loop = asyncio.get_running_loop()
        write = request.is_write or bool(request.text)
        kind = JobKind.WRITE if write else JobKind.READ
        priority = Priority.WRITE if write else Priority.READ
        fmt = ParameterDescription(vtype=vtype)
        job = Job(self.drive, request, kind, priority, deadline, fmt, loop.create_future())
        self.runner.submit(job)
        assert job.future is not None
        await asyncio.wait([job.future, ended], return_when=asyncio.FIRST_COMPLETED)
        if job.future.done():
            return job.future.result()
        return ended.result()  # raises what ended the session

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
            await self.wire.port.close()


async def run_job(
    line: Line,
    target: DriveTarget,
    request: pkw.PkwRequest,
    *,
    retries: int = 2,
    deadline: float,
) -> Outcome:
    """One job on an open line, by the service's planner (no other drive, no polls)."""
    finished = await perform(line, target, request, retries=retries, deadline=deadline)
    return finished.outcome


async def perform(
    line: Line,
    target: DriveTarget,
    request: pkw.PkwRequest,
    *,
    retries: int = 2,
    deadline: float,
) -> Finished:
    """:func:`run_job`, with what its exchanges cost (``tally``)."""
    loop = asyncio.get_running_loop()
    planner = Planner(
        [DriveSpec("drive", carrier_for(target))], poll_deadline=deadline, retries=retries
    )
    planner.line_up(loop.time())
    kind = JobKind.WRITE if request.is_write else JobKind.READ
    priority = Priority.WRITE if request.is_write else Priority.READ
    planner.submit(Job("drive", request, kind, priority, deadline), loop.time())
    while True:
        for event in planner.take_events():
            if isinstance(event, Finished) and isinstance(event.work, Job):
                return event
        action = planner.next_action(loop.time())
        if isinstance(action, Send):
            result = await line.exchange(action.address, action.telegram)
            planner.exchanged(action, result, loop.time())
        elif not planner.events:  # nothing to do before the job's deadline: it has ended
            await asyncio.sleep(max(0.0, min(action.until, deadline) - loop.time()))
