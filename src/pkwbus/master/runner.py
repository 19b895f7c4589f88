"""The one runner of a line, whatever its bus: a planner, a wire, a port, one stream.

The policy is the planner's (:mod:`pkwbus.master.planning`); what goes out on
the bus and what an answer means is the wire's (:class:`Wire`: FC and USS,
:mod:`pkwbus.master.wires.serial`; PROFIBUS DP, :mod:`pkwbus.master.wires.profibus`),
a few pure calls that the runner makes and that never reach back into it, as
profirust's FDL station drives its application (``transmit``, ``receive``,
``handle_timeout``). The runner is given the line's port (:class:`Port`) and
its wire apart, of the same requests and answers (both generic over them:
a port of one bus and a wire of another do not type-check), and is the only
one that opens and closes the port, starts each request and hands its answer
over; a wire never holds its port.

A run of exchanges goes on in the port's callbacks: each answer goes to the
wire, the next request starts from the same callback while the line's start
pause runs, until the wire has nothing to send now; then the runner idles until
the wire's time, or until a job comes in.

Everything that happens - the planner's events, the wire's, the port's state -
is one stream of events (:mod:`pkwbus.master.events`), recorded in batches at
most :data:`BATCH_EVERY` seconds after the first of a batch (a loop timer), each
with its time: the snapshot's one writer first, then the observers given. What
someone waits for is recorded at once: a finished write or on-demand read (its
caller), a drive's change of health (its log line); so is everything at the end
of a run, when the port fails, and when the line stops. A line never stops for
an error: it is reported, the port given up and reopened at back-off.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import deque
from collections.abc import Callable, Collection, Sequence
from typing import Generic, TypeVar

from pkwbus.link import Link, LinkState, PortError
from pkwbus.master import told
from pkwbus.master.bus import Done, LineRefused, Port, Wire
from pkwbus.master.events import Event, LineState, MaintenanceChanged, Observer, SettingsSeen
from pkwbus.master.planning.carrier import Item, Preview
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.jobs import Job, ProbeJob
from pkwbus.master.planning.plan import DriveSpec, Finished, HealthChanged, Idle
from pkwbus.master.planning.planner import Planner
from pkwbus.master.snapshot import Maintained, Snapshot
from pkwbus.master.snapshot_writer import SnapshotWriter
from pkwbus.waiting import wait_event

__all__ = ["BATCH_EVERY", "Done", "LineRefused", "LineRunner", "Port", "Wire"]

log = logging.getLogger(__name__)

Request = TypeVar("Request")  # what the line's wire sends and its port carries
Answer = TypeVar("Answer")  # what comes back: from the port, to the wire

# Seconds at most between two batches of recorded events during a run.
BATCH_EVERY = 0.05


def _waited_for(events: Sequence[Event]) -> bool:
    """Whether any of ``events`` is one somebody waits for: record it at once."""
    for event in events:  # by type: Finished and HealthChanged have no subclass
        if type(event) is Finished:
            if isinstance(event.work, Job):
                return True
        elif type(event) is HealthChanged:
            return True
    return False


class LineRunner(Generic[Request, Answer]):
    """Runs one line of any bus: the service's task for it."""

    _request: Request  # the request out (set before the port is given it)

    def __init__(
        self,
        name: str,
        port: Port[Request, Answer],
        wire: Wire[Request, Answer],
        drives: Sequence[DriveSpec],
        *,
        retries: int = 2,
        policy: HealthPolicy | None = None,
        snapshot: Snapshot | None = None,
        observers: Sequence[Observer] = (),
        poll_deadline: float | None = None,
        wall_clock: Callable[[], float] = time.time,
        batch_every: float = BATCH_EVERY,
        log_port: bool = True,
    ) -> None:
        self.name = name
        self._log_port = log_port  # a port that fails, logged (a command says it itself)
        self.port = port
        self.wire = wire
        self.snapshot = snapshot if snapshot is not None else Snapshot()
        self.observers = list(observers)
        self.writer = SnapshotWriter(name, drives, self.snapshot)
        self.planner = Planner(
            drives, poll_deadline=poll_deadline or wire.poll_deadline(retries), retries=retries,
            policy=policy,
        )  # fmt: skip
        self.stopping = False
        self._wake = asyncio.Event()
        self._unrecorded: deque[tuple[list[Event], float]] = deque()
        self._record_timer: asyncio.TimerHandle | None = None  # the batch's deadline
        self._wall = wall_clock  # the events' time of day
        self._record_every = batch_every
        self._loop: asyncio.AbstractEventLoop | None = None
        self._run_over: asyncio.Future[float | None] | None = None  # one per run of exchanges
        self._started = 0.0
        self._refusing = False
        self._collect()  # what the wire tells from the start (a DP slave offline)
        port.link.reconnect.add_listener(self._on_port)

    @property
    def link(self) -> Link:
        return self.port.link

    # ------------------------------------------------------------ the service's

    def submit(self, job: Job | ProbeJob) -> None:
        """Queue a write, an on-demand read or a probe; its future gets the result."""
        self.planner.submit(job, asyncio.get_running_loop().time())
        self.flush()
        self._wake.set()

    def preview(self, drive: str, item: Item) -> Preview:
        """``item``'s request as ``drive``'s carrier would send it now (a dry run's bytes);
        LocalProtocolError for one it cannot carry, KeyError for a drive not here."""
        return self.planner.drive(drive).carrier.preview(item)

    def maintenance(
        self, drive: str, on: bool, reason: str = "", since: float | None = None
    ) -> None:
        """Put ``drive`` in maintenance (nothing goes out to it, not even a probe or a DP
        Data_Exchange) or take it out (a drive that came back); KeyError: not here.
        ``since``: one kept from before (a reload), shown with its reason and since."""
        shown = self.snapshot.maintenance.get(drive)
        if self.planner.drive(drive).maintenance == on:  # KeyError: an unknown drive
            kept = since is None or shown == Maintained(reason, since)
            if (on and kept) or (not on and shown is None):
                return  # as it was: its reason and since stay
        else:
            now = asyncio.get_running_loop().time()
            self.planner.maintenance(drive, on, now)
            self.wire.leave_out(self.planner, drive, on, now)
        self._unrecorded.append(([MaintenanceChanged(drive, on, reason)], since or self._wall()))
        self.flush()
        self._wake.set()

    def settings_seen(self, drive: str, changed: int | None, swept: float | None) -> None:
        """What the sweep of ``drive``'s settings found, into the read model
        (:class:`~pkwbus.master.events.SettingsSeen`)."""
        self.tell([SettingsSeen(drive, changed, swept)])

    # A reload: the line's drives and polls change while its port stays open and its other
    # drives go on as they were.

    def add_drive(self, spec: DriveSpec) -> None:
        """A drive added to the line: polled from now on, as a drive at the start is."""
        self.writer.add_drive(spec)
        self.planner.add_drive(spec, asyncio.get_running_loop().time())
        self._changed()

    def remove_drive(self, drive: str, reason: str) -> bool:
        """A drive gone from the line: its jobs end with ``reason``, nothing more goes out to
        it, nothing of it is shown; whether an exchange of it was out (its end: line time)."""
        out = self.planner.drive(drive).busy
        self.planner.remove_drive(drive, reason, asyncio.get_running_loop().time())
        self.flush()  # what ended, to its callers and the observers, before it is forgotten
        self.writer.remove_drive(drive, exchange_out=out)
        return out

    def update_polls(self, spec: DriveSpec, restated: Collection[tuple[int, int]] = ()) -> None:
        """The drive's polls and described parameters now (``spec``, its carrier and form as
        they were): a kept poll goes on at its due time, a new one is due now, the values of
        those gone and the latest decoded otherwise now (``restated``) leave (KeyError)."""
        now = asyncio.get_running_loop().time()
        self.writer.update_polls(spec, self.planner.update_polls(spec, now), restated)
        self._changed()

    def forget(self) -> None:
        """The line gone from the configuration, after :meth:`run` ended: nothing of it
        stays in the snapshot."""
        self.writer.forget_line()

    def _changed(self) -> None:
        self.flush()
        self._wake.set()

    def stop(self) -> None:
        """Take no new jobs; what is in flight finishes, then :meth:`run` returns."""
        self.stopping = True
        self._wake.set()

    async def open(self) -> None:
        """Open the port now (PortError with the reason, LineRefused), before :meth:`run`:
        a command that must know at once."""
        await self.link.open()
        try:
            await self.port.started()
        except LineRefused as exc:
            self._refused(exc)
            raise

    async def close(self) -> None:
        """Close the port that :meth:`open` opened where :meth:`run` never ran (a run
        closes it as it ends)."""
        await self.port.close()

    async def run(self) -> None:
        loop = self._loop = asyncio.get_running_loop()
        link = self.link
        if link.is_open:  # opened by :meth:`open` before
            self.planner.line_up(loop.time())
        try:
            while not self.stopping:
                try:
                    await self._step(loop, link)
                except LineRefused as exc:
                    self._refused(exc)
                except Exception as exc:  # a line never stops: report, reopen, go on
                    log.exception("line %s: unexpected error, reopening its port", self.name,
                                  extra={"line": self.name})  # fmt: skip
                    if link.is_open:
                        link.abort(f"unexpected error: {exc!r}")
        finally:
            self.planner.stop("the service is stopping")
            self.flush()
            with contextlib.suppress(Exception):
                await self.port.close()
            self.writer.apply([LineState(self.name, False)])

    def _refused(self, exc: LineRefused) -> None:
        told.port(self.name, logging.ERROR, str(exc), self.link.reconnect.told(str(exc)))
        if self.link.is_open:
            self._refusing = True  # told with the loss it causes
            try:
                self.link.abort(str(exc))
            finally:
                self._refusing = False

    async def _step(self, loop: asyncio.AbstractEventLoop, link: Link) -> None:
        if not link.is_open:
            self.planner.line_down(loop.time())
            self.flush()
            if await link.reopen(self._wake) and not self.stopping:
                await self.port.started()
                if link.is_open:
                    self.planner.line_up(loop.time())
            return
        try:
            until = await self._carry(loop)
        except PortError as exc:  # the port found gone
            if isinstance(exc, LineRefused):
                raise
            if link.is_open:
                link.abort(str(exc))
            return
        self.flush()
        if until is not None and not self.stopping:
            await self._idle(loop, until)

    async def _carry(self, loop: asyncio.AbstractEventLoop) -> float | None:
        """One run of exchanges; the time the line may idle until (None: ask again now)."""
        action = self.wire.transmit(self.planner, loop.time())
        self._collect()
        if isinstance(action, Idle):
            return action.until
        over = self._run_over = loop.create_future()
        self._start(action, loop)
        self.flush()
        until: float | None = await over
        return until

    def _start(self, request: Request, loop: asyncio.AbstractEventLoop) -> None:
        self._request = request
        self._started = loop.time()
        self.port.start(request, self._done)

    def _done(self, answer: Answer | BaseException) -> None:
        """The port's callback: the answer to the wire, the next request out."""
        over = self._run_over
        try:
            if isinstance(answer, BaseException):
                raise answer
            loop = self._loop
            assert loop is not None
            now = loop.time()
            wire, planner, port = self.wire, self.planner, self.port
            wire.received(planner, self._request, answer, now, now - self._started,
                          now - port.sent_at)  # fmt: skip
            until: float | None = None
            if not self.stopping and port.link.is_open:
                action = wire.transmit(planner, now)
                if not isinstance(action, Idle):
                    self._start(action, loop)
                    self._collect()  # recorded while the start pause runs
                    return
                until = action.until
            self._collect()
            self.flush()
        except BaseException as exc:  # the runner's task reports it and reopens the port
            self._run_over = None
            if over is not None and not over.done():
                over.set_exception(exc)
            return
        self._run_over = None
        if over is not None and not over.done():
            over.set_result(until)

    async def _idle(self, loop: asyncio.AbstractEventLoop, until: float) -> None:
        delay = until - loop.time()
        if delay <= 0:
            return
        self._wake.clear()
        await wait_event(self._wake, delay)

    # ------------------------------------------------------------ the stream

    def _taken(self) -> list[Event]:
        """The wire's new events, then the planner's (each exchange before what it led to)."""
        events: list[Event] = self.wire.take_events()
        planned = self.planner.take_events()
        if planned:
            events += planned
        return events

    def _collect(self) -> None:
        """The planner's and the wire's new events, into the batch; what somebody waits
        for is recorded at once."""
        events = self._taken()
        if events:
            self.tell(events)

    def tell(self, events: list[Event]) -> None:
        """Events for the batch; what somebody waits for is recorded at once."""
        if self._record_timer is None:  # a batch begins
            self._arm()
        self._unrecorded.append((events, self._wall()))
        if _waited_for(events):
            self.flush()

    def _arm(self) -> None:
        loop = asyncio.get_running_loop()
        self._record_timer = loop.call_later(self._record_every, self._on_record_timer)

    def flush(self) -> None:
        """Record everything not recorded yet, in order: the snapshot's writer first, each event
        with its time, then every observer, the whole batch in one call. What the writer
        has not taken when it raises stays queued."""
        if self._record_timer is not None:
            self._record_timer.cancel()
            self._record_timer = None
        self._collect_quietly()
        unrecorded = self._unrecorded
        batch: list[Event] = []
        while unrecorded:
            events, at = unrecorded[0]
            made = self.writer.apply(events, at)
            unrecorded.popleft()
            batch += events
            if made:
                batch += made
        if batch:
            for observer in self.observers:
                observer.on_events(batch)

    def _collect_quietly(self) -> None:
        events = self._taken()
        if events:
            self._unrecorded.append((events, self._wall()))

    def _on_record_timer(self) -> None:
        self._record_timer = None
        try:
            self.flush()
        except Exception:  # a line never stops; the rest of the batch stays queued
            log.exception("line %s: recording failed", self.name, extra={"line": self.name})

    def _on_port(self, state: LinkState, error: str | None) -> None:
        repeated = self.link.reconnect.repeated  # in an outage told already: not again
        if state is LinkState.OPEN:
            told.port(self.name, logging.INFO, f"port {self.link.settings.url} open", repeated)
            self._unrecorded.append(([LineState(self.name, True)], self._wall()))
        elif state is LinkState.FAILED:
            if self._log_port:
                told.port(self.name, logging.WARNING, str(error), repeated)
            self.planner.port_failed()
            self.wire.lost()
            state_event = LineState(self.name, False, error, refused=self._refusing)
            self._unrecorded.append(([state_event], self._wall()))
            self.flush()
        else:
            self._unrecorded.append(([LineState(self.name, False)], self._wall()))
