"""The runner of one line: feeds its planner from the port, one exchange at a time.

The policy is the planner's (:mod:`pkwbus.master.planner`); what its events
mean is :mod:`pkwbus.master.record`'s. The exchanges run in the line's
callbacks: each result goes to the planner, and the next exchange starts
from the same callback. The runner's task only waits: for the port to
reopen (the line's reconnect object says when), for a run of exchanges to
end, or idle until something is due or a job comes in. :func:`run_job`
drives one job the same way, for the command line.

During a run of exchanges, polls' values and the exchanges' counters are
recorded in batches, at most :data:`RECORD_EVERY` seconds after the first
exchange of the batch (a loop timer), each with the time it happened: one
batch of the same work keeps the interpreter's caches warm, where the same
work between every two wake-ups runs cold. What someone waits for is
recorded at once: a finished write or on-demand read (its caller), a
drive's change of health (its log line); so is everything at the end of a
run, when the port fails, and when the line stops.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import deque
from collections.abc import Callable, Sequence

from pkwbus.link import LinkState, PortError
from pkwbus.master.health import HealthPolicy
from pkwbus.master.jobs import Job, JobKind, Priority
from pkwbus.master.line import Line
from pkwbus.master.plan import DriveSpec, Event, Finished, HealthChanged, PollSpec, Send
from pkwbus.master.planner import Planner
from pkwbus.master.record import LineEvents, LineRecord, NoEvents
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import ExchangeResult, Outcome
from pkwbus.protocol import pkw

__all__ = [
    "RECORD_EVERY", "DriveSpec", "LineEvents", "LineScheduler", "NoEvents", "PollSpec",
    "perform", "run_job",
]  # fmt: skip

log = logging.getLogger(__name__)

# Seconds at most between two batches of recorded polls and counters during a run.
RECORD_EVERY = 0.05


def _waited_for(events: list[Event]) -> bool:
    """Whether any of ``events`` is one somebody waits for: record it at once."""
    for event in events:
        if isinstance(event, Finished):
            if isinstance(event.work, Job):
                return True
        elif isinstance(event, HealthChanged):
            return True
    return False


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
        wall_clock: Callable[[], float] = time.time,
        record_every: float = RECORD_EVERY,
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
        # Not yet recorded: the exchanges, the planner's events with their wall time.
        self._exchanges: deque[tuple[str, ExchangeResult, float]] = deque()
        self._unrecorded: deque[tuple[list[Event], float]] = deque()
        self._record_timer: asyncio.TimerHandle | None = None  # the batch's deadline
        self._wall = wall_clock  # the events' time of day
        self._record_every = record_every
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
            if self._record_timer is None:  # a batch begins: recorded RECORD_EVERY later
                self._record_timer = loop.call_later(self._record_every, self._on_record_timer)
            self._exchanges.append((send.drive, result, now - self._sent_at))
            planner = self.planner
            planner.exchanged(send, result, now)
            if not self._stopping and self.line.is_open:
                action = planner.next_action(now)
                if isinstance(action, Send):
                    self._start(action, loop)
                    self._batch()  # while the start pause runs
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

    def _batch(self) -> None:
        """Keep the planner's events for the batch; what somebody waits for, at once."""
        planner = self.planner
        if planner.events:
            events = planner.take_events()
            self._unrecorded.append((events, self._wall()))
            if _waited_for(events):
                self._flush()

    def _on_record_timer(self) -> None:
        self._record_timer = None
        try:
            self._flush()
        except Exception:  # a line never stops; the rest of the batch stays queued
            log.exception("line %s: recording failed", self.name, extra={"line": self.name})

    def _flush(self) -> None:
        """Record everything not recorded yet, in order: each exchange before the
        events it led to. What is not recorded when one of them raises stays queued."""
        if self._record_timer is not None:
            self._record_timer.cancel()
            self._record_timer = None
        exchanges = self._exchanges
        exchange = self.events.exchange
        while exchanges:
            exchange(*exchanges.popleft())
        unrecorded = self._unrecorded
        while unrecorded:
            events, at = unrecorded.popleft()
            self.record.apply(events, at)
        if self.planner.events:
            self.record.apply(self.planner.take_events(), self._wall())

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
