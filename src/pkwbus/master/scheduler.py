"""The runner of one line: feeds its planner from the port, one exchange at a time.

The policy is the planner's (:mod:`pkwbus.master.planner`); what its events
mean is :mod:`pkwbus.master.record`'s. The exchanges run in the line's
callbacks: each result goes to the planner, and the next exchange starts
from the same callback, before the events of the last one are recorded (that
work uses up the start pause). The runner's task only waits: for the port
to reopen (the line's reconnect object says when), for a run of exchanges
to end, or idle until something is due or a job comes in. :func:`run_job`
drives one job the same way, for the command line.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Sequence

from pkwbus.link import LinkState, PortError
from pkwbus.master.health import HealthPolicy
from pkwbus.master.jobs import Job, JobKind, Priority
from pkwbus.master.line import Line
from pkwbus.master.plan import DriveSpec, Finished, PollSpec, Send
from pkwbus.master.planner import Planner
from pkwbus.master.record import LineEvents, LineRecord, NoEvents
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import ExchangeResult, Outcome
from pkwbus.protocol import pkw

__all__ = [
    "DriveSpec", "LineEvents", "LineScheduler", "NoEvents", "PollSpec", "perform", "run_job",
]  # fmt: skip

log = logging.getLogger(__name__)


class LineScheduler:
    """Runs one line: the service's task for it."""

    def __init__(
        self,
        name: str,
        line: Line,
        drives: Sequence[DriveSpec],
        *,
        retries: int = 2,
        policy: HealthPolicy | None = None,
        snapshot: Snapshot | None = None,
        events: LineEvents | None = None,
        poll_deadline: float | None = None,
    ) -> None:
        self.name = name
        self.line = line
        self.snapshot = snapshot if snapshot is not None else Snapshot()
        self.events: LineEvents = events or NoEvents()
        self.record = LineRecord(name, drives, self.snapshot, self.events)
        # Long enough for the retries and a lagging answer.
        deadline = poll_deadline or 4 * (retries + 1) * line.timeout
        self.planner = Planner(drives, poll_deadline=deadline, retries=retries, policy=policy)
        self._wake = asyncio.Event()
        self._stopping = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._run_over: asyncio.Future[None] | None = None  # one per run of exchanges
        self._send: Send | None = None
        self._sent_at = 0.0
        line.reconnect.add_listener(self._on_port)

    def submit(self, job: Job) -> None:
        """Queue a write or on-demand read; its future gets the result."""
        self.planner.submit(job, asyncio.get_running_loop().time())
        self._flush()
        self._wake.set()

    def stop(self) -> None:
        """Take no new jobs; the exchange in flight finishes, then :meth:`run` returns."""
        self._stopping = True
        self._wake.set()

    async def run(self) -> None:
        loop = self._loop = asyncio.get_running_loop()
        if self.line.is_open:  # opened by its owner before
            self.planner.line_up(loop.time())
        try:
            while not self._stopping:
                try:
                    await self._step(loop)
                except Exception as exc:  # a line never stops: report, reopen, go on
                    log.exception(
                        "line %s: unexpected error, reopening its port",
                        self.name,
                        extra={"line": self.name},
                    )
                    self.line.abort(f"unexpected error: {exc!r}")
        finally:
            self.planner.stop("the service is stopping")
            self._flush()
            await self.line.close()
            self.snapshot.lines[self.name] = False

    async def _step(self, loop: asyncio.AbstractEventLoop) -> None:
        planner = self.planner
        if not self.line.is_open:
            planner.line_down(loop.time())
            self._flush()
            await self._reopen(loop)
            return
        action = planner.next_action(loop.time())
        if isinstance(action, Send):
            over = self._run_over = loop.create_future()
            self._start(action, loop)
            self._flush()
            await over
        else:
            self._flush()
            if not self._stopping:
                await self._idle(loop, action.until)

    def _start(self, send: Send, loop: asyncio.AbstractEventLoop) -> None:
        self._send = send
        self._sent_at = loop.time()
        self.line.start(send.target.adr, send.telegram, self._exchanged)

    def _exchanged(self, result: ExchangeResult) -> None:
        """The line's callback: account for the result, start the next exchange."""
        over = self._run_over
        try:
            send, self._send = self._send, None
            loop = self._loop
            assert send is not None and loop is not None
            now = loop.time()
            self.events.exchange(send.drive, result, now - self._sent_at)
            planner = self.planner
            planner.exchanged(send, result, now)
            if not self._stopping and self.line.is_open:
                action = planner.next_action(now)
                if isinstance(action, Send):
                    self._start(action, loop)
                    self._flush()  # while the start pause runs
                    return
            self._flush()
        except Exception as exc:  # the runner's task reports it and reopens the port
            self._run_over = None
            if over is not None and not over.done():
                over.set_exception(exc)
            return
        self._run_over = None
        if over is not None and not over.done():
            over.set_result(None)

    async def _reopen(self, loop: asyncio.AbstractEventLoop) -> None:
        reconnect = self.line.reconnect
        if reconnect.wait(loop.time()) > 0:
            await self._idle(loop, reconnect.next_attempt)
            if self._stopping or reconnect.wait(loop.time()) > 0:
                return  # woken by a new job: it failed at once, the back-off stands
        with contextlib.suppress(PortError):  # reported once by the reconnect listener
            await self.line.open()
        if self.line.is_open:
            self.planner.line_up(loop.time())

    async def _idle(self, loop: asyncio.AbstractEventLoop, until: float) -> None:
        delay = until - loop.time()
        if delay <= 0:
            return
        self._wake.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._wake.wait(), delay)

    def _flush(self) -> None:
        if self.planner.events:
            self.record.apply(self.planner.take_events())

    def _on_port(self, state: LinkState, error: str | None) -> None:
        up = state is LinkState.OPEN
        self.snapshot.lines[self.name] = up
        ctx = {"line": self.name}
        if up:
            log.info("line %s: port %s open", self.name, self.line.link.settings.url, extra=ctx)
        elif state is LinkState.FAILED:
            log.warning("line %s: %s", self.name, error, extra=ctx)
            self.planner.port_failed()
            self._flush()


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
    planner = Planner([DriveSpec("drive", target)], poll_deadline=deadline, retries=retries)
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
            result = await line.exchange(action.target, action.telegram)
            planner.exchanged(action, result, loop.time())
        elif not planner.events:  # nothing to do before the job's deadline: it has ended
            await asyncio.sleep(max(0.0, min(action.until, deadline) - loop.time()))
