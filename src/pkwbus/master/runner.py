"""The one runner of a line, whatever its bus: a planner fed through a wire, one recorder.

The policy is the planner's (:mod:`pkwbus.master.planning.planner`); how exchanges
travel is the wire's (:class:`Wire`): FC and USS one exchange at a time
(:mod:`pkwbus.master.wires.serial.wire`), PROFIBUS DP a cycle through the slaves
(:mod:`pkwbus.master.wires.profibus.wire`), as one ``poll(now, phy, app)`` drives any
application in profirust. What the planner's events mean (values into the
snapshot, job futures, metrics) is the recorder's (:mod:`pkwbus.master.recorder`),
the only writer of the snapshot.

The wire's port (its :class:`~pkwbus.link.Link`) owns the port's state and
back-off; the runner listens there, and reopens the port through it when it
is due. A line never stops for an error: it is reported, the port given up
and reopened at back-off.

During a run of exchanges, the exchanges' counters and the planner's events
are recorded in batches, at most :data:`RECORD_EVERY` seconds after the first
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
from typing import Protocol

from pkwbus.link import Link, LinkState, PortError
from pkwbus.master.planning.answers import ExchangeResult
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.jobs import Job
from pkwbus.master.planning.plan import DriveSpec, Event, Finished, HealthChanged
from pkwbus.master.planning.planner import Planner
from pkwbus.master.recorder import LineEvents, LineRecord, NoEvents
from pkwbus.master.snapshot import Snapshot

__all__ = ["RECORD_EVERY", "LineRunner", "Wire"]

log = logging.getLogger(__name__)

# Seconds at most between two batches of recorded polls and counters during a run.
RECORD_EVERY = 0.05


class Wire(Protocol):
    """A kind of line under the runner: how its exchanges travel."""

    @property
    def link(self) -> Link:
        """The port: its state, back-off and listeners."""
        ...

    def planner_for(
        self, drives: Sequence[DriveSpec], retries: int, policy: HealthPolicy | None,
        poll_deadline: float | None,
    ) -> Planner: ...  # fmt: skip

    def attach(self, runner: LineRunner) -> None:
        """Called once, before anything runs: the runner whose planner and recorder it feeds."""
        ...

    async def started(self) -> None:
        """The port just opened: what the wire does before its first request (DP listens)."""
        ...

    async def carry(self) -> float | None:
        """Exchanges, as many as the planner has ready; the time the line may idle until."""
        ...

    def lost(self) -> None:
        """The port is gone: what the wire had under way starts afresh."""
        ...

    async def close(self) -> None:
        """The line stops: close the port (what the bus asks first, first)."""
        ...


def _waited_for(events: list[Event]) -> bool:
    """Whether any of ``events`` is one somebody waits for: record it at once."""
    for event in events:
        if isinstance(event, Finished):
            if isinstance(event.work, Job):
                return True
        elif isinstance(event, HealthChanged):
            return True
    return False


class LineRunner:
    """Runs one line of any bus: the service's task for it."""

    def __init__(
        self,
        name: str,
        wire: Wire,
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
        self.wire = wire
        self.snapshot = snapshot if snapshot is not None else Snapshot()
        self.events: LineEvents = events or NoEvents()
        self.record = LineRecord(name, drives, self.snapshot, self.events)
        self.planner = wire.planner_for(drives, retries, policy, poll_deadline)
        self.stopping = False
        self._wake = asyncio.Event()
        # Not yet recorded: the exchanges, the planner's events with their wall time.
        self._exchanges: deque[tuple[str, ExchangeResult, float]] = deque()
        self._unrecorded: deque[tuple[list[Event], float]] = deque()
        self._record_timer: asyncio.TimerHandle | None = None  # the batch's deadline
        self._wall = wall_clock  # the events' time of day
        self._record_every = record_every
        wire.link.reconnect.add_listener(self._on_port)
        wire.attach(self)

    # ------------------------------------------------------------ the service's

    def submit(self, job: Job) -> None:
        """Queue a write or on-demand read; its future gets the result."""
        self.planner.submit(job, asyncio.get_running_loop().time())
        self.flush()
        self._wake.set()

    def stop(self) -> None:
        """Take no new jobs; what is in flight finishes, then :meth:`run` returns."""
        self.stopping = True
        self._wake.set()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        link = self.wire.link
        if link.is_open:  # opened by its owner before
            self.planner.line_up(loop.time())
        try:
            while not self.stopping:
                try:
                    await self._step(loop, link)
                except Exception as exc:  # a line never stops: report, reopen, go on
                    log.exception(
                        "line %s: unexpected error, reopening its port",
                        self.name,
                        extra={"line": self.name},
                    )
                    if link.is_open:
                        link.abort(f"unexpected error: {exc!r}")
        finally:
            self.planner.stop("the service is stopping")
            self.flush()
            with contextlib.suppress(Exception):
                await self.wire.close()
            self.snapshot.lines[self.name] = False

    async def _step(self, loop: asyncio.AbstractEventLoop, link: Link) -> None:
        if not link.is_open:
            self.planner.line_down(loop.time())
            self.flush()
            if await link.reopen(self._wake) and not self.stopping:
                await self.wire.started()
                if link.is_open:
                    self.planner.line_up(loop.time())
            return
        try:
            until = await self.wire.carry()
        except PortError as exc:  # the wire found the port gone
            if link.is_open:
                link.abort(str(exc))
            return
        self.flush()
        if until is not None and not self.stopping:
            await self._idle(loop, until)

    async def _idle(self, loop: asyncio.AbstractEventLoop, until: float) -> None:
        delay = until - loop.time()
        if delay <= 0:
            return
        self._wake.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._wake.wait(), delay)

    # ------------------------------------------------------------ the wire's

    def exchanged(self, drive: str, result: ExchangeResult, busy: float) -> None:
        """An exchange with ``drive`` is over (it held the line ``busy`` seconds): recorded
        with its batch, at most :data:`RECORD_EVERY` seconds from now."""
        if self._record_timer is None:  # a batch begins
            self._arm()
        self._exchanges.append((drive, result, busy))

    def batch(self) -> None:
        """Keep the planner's events for the batch; what somebody waits for, at once."""
        planner = self.planner
        if planner.events:
            self.tell(planner.take_events())

    def tell(self, events: list[Event]) -> None:
        """Events for the batch (the planner's, or a DP slave's status word from its PZD);
        what somebody waits for is recorded at once."""
        if self._record_timer is None:  # a batch begins
            self._arm()
        self._unrecorded.append((events, self._wall()))
        if _waited_for(events):
            self.flush()

    def _arm(self) -> None:
        loop = asyncio.get_running_loop()
        self._record_timer = loop.call_later(self._record_every, self._on_record_timer)

    def flush(self) -> None:
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

    def _on_record_timer(self) -> None:
        self._record_timer = None
        try:
            self.flush()
        except Exception:  # a line never stops; the rest of the batch stays queued
            log.exception("line %s: recording failed", self.name, extra={"line": self.name})

    def _on_port(self, state: LinkState, error: str | None) -> None:
        up = state is LinkState.OPEN
        self.snapshot.lines[self.name] = up
        ctx = {"line": self.name}
        if up:
            log.info("line %s: port %s open", self.name, self.wire.link.settings.url, extra=ctx)
        elif state is LinkState.FAILED:
            log.warning("line %s: %s", self.name, error, extra=ctx)
            self.planner.port_failed()
            self.wire.lost()
            self.flush()
