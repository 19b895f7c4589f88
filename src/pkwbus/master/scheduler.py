"""What a line sends next: writes, then on-demand reads, then due polls.

One scheduler per line, one exchange at a time. Each drive has at most one
PKW transaction in flight (its parameter channel holds one request). While
a drive's answer lags ("not yet"), another drive's exchange goes between
its repeats. A drive that stops answering is down after a few consecutive
failures and is then probed with one short telegram at capped exponential
back-off, so that it costs the line almost nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import logging
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

from pkwbus.link import LinkState, PortError
from pkwbus.master.health import DriveHealth, HealthPolicy
from pkwbus.master.jobs import Cancelled, Job, JobKind, JobResult, Priority
from pkwbus.master.line import Line
from pkwbus.master.snapshot import DriveState, Reading, Snapshot
from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import (
    Answered,
    ErrorKind,
    ExchangeResult,
    Failure,
    LineFailed,
    Outcome,
    PkwTransaction,
    Reply,
    TimedOut,
)
from pkwbus.master.values import ParameterFormat
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.telegram import split_block

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PollSpec:
    """One parameter a drive is polled for, every ``every`` seconds."""

    parameter: str  # as configured: the metric label
    index: int
    request: pkw.PkwRequest
    every: float
    fmt: ParameterFormat = field(default_factory=ParameterFormat)


@dataclass(frozen=True)
class DriveSpec:
    name: str
    target: DriveTarget
    polls: tuple[PollSpec, ...] = ()


class LineEvents(Protocol):
    """What the scheduler reports (the service turns it into metrics)."""

    def exchange(self, drive: str, result: ExchangeResult, busy: float) -> None: ...
    def job_finished(self, drive: str, job: Job, result: JobResult) -> None: ...
    def overrun(self, drive: str) -> None: ...


class NoEvents:
    def exchange(self, drive: str, result: ExchangeResult, busy: float) -> None:
        pass

    def job_finished(self, drive: str, job: Job, result: JobResult) -> None:
        pass

    def overrun(self, drive: str) -> None:
        pass


class _Poll:
    __slots__ = ("due", "spec")

    def __init__(self, spec: PollSpec, due: float) -> None:
        self.spec = spec
        self.due = due


@dataclass(eq=False)
class _Active:
    tx: PkwTransaction
    priority: Priority
    order: float
    job: Job | None = None
    poll: _Poll | None = None


class _Drive:
    def __init__(self, spec: DriveSpec, policy: HealthPolicy, start: float, slot: int = 0) -> None:
        self.spec = spec
        self.slot = slot  # position in the scheduler's list
        self.name = spec.name
        self.target = spec.target
        self.health = DriveHealth(policy)
        self.writes: deque[Job] = deque()
        self.reads: deque[Job] = deque()
        self.active: _Active | None = None
        self.lagging = False
        self._seq = itertools.count()
        self.polls: list[tuple[float, int, _Poll]] = []
        for p in spec.polls:
            self.push_poll(_Poll(p, start))

    def push_poll(self, poll: _Poll) -> None:
        heapq.heappush(self.polls, (poll.due, next(self._seq), poll))

    def restart_polls(self, now: float) -> None:
        """Every poll due now: after the drive was down, none of them is late."""
        polls = [entry[2] for entry in self.polls]
        self.polls.clear()
        for poll in polls:
            poll.due = now
            self.push_poll(poll)


_Action = tuple[_Drive, bytes, bool]  # drive, telegram, is a probe


class LineScheduler:
    """Runs one line: decides every exchange, keeps the snapshot, reports events."""

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
        self.retries = retries
        self.policy = policy or HealthPolicy()
        self.snapshot = snapshot if snapshot is not None else Snapshot()
        self.events: LineEvents = events or NoEvents()
        self.poll_deadline = poll_deadline
        self._specs = list(drives)
        self._drives: list[_Drive] = []
        self._by_name: dict[str, _Drive] = {}
        self._rr = 0
        self._job_seq = itertools.count()
        self._lagging: list[_Drive] = []  # drives whose last answer was "not yet"
        self._wake = asyncio.Event()
        self._stopping = False
        self.line.link.on_state = self._on_link_state
        self.snapshot.lines[name] = False
        for spec in drives:
            self.snapshot.drives[spec.name] = DriveState()

    # -------------------------------------------------------------- API

    def has_drive(self, name: str) -> bool:
        return any(s.name == name for s in self._specs)

    def submit(self, job: Job) -> None:
        """Queue a write or on-demand read; its future gets the result."""
        drive = self._by_name.get(job.drive)
        if drive is None:
            raise KeyError(job.drive)
        if self._stopping:
            job.resolve(JobResult(Cancelled("the service is stopping")))
            return
        (drive.writes if job.priority is Priority.WRITE else drive.reads).append(job)
        self._wake.set()

    def stop(self) -> None:
        """Take no new jobs; the exchange in flight finishes, then :meth:`run` returns."""
        self._stopping = True
        self._wake.set()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        start = loop.time()
        self._drives = [_Drive(s, self.policy, start, i) for i, s in enumerate(self._specs)]
        self._by_name = {d.name: d for d in self._drives}
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
                    self.line.link.abort(f"unexpected error: {exc!r}")
        finally:
            self._cancel_all("the service is stopping")
            await self.line.close()
            self.snapshot.lines[self.name] = False

    async def _step(self, loop: asyncio.AbstractEventLoop) -> None:
        if not self.line.link.is_open:
            await self._reopen()
            return
        action, wake = self._pick(loop.time())
        if action is None:
            await self._idle(wake)
            return
        await self._perform(action)

    # ------------------------------------------------------------ choice

    def _pick(self, now: float) -> tuple[_Action | None, float]:
        best: _Drive | None = None
        best_key: tuple[int, int, float] | None = None
        wake = now + 3600.0
        drives = self._drives
        n = len(drives)
        for i in range(n):
            d = drives[(self._rr + i) % n]
            key, next_time = self._candidate(d, now)
            if key is None:
                wake = min(wake, next_time)
            elif best_key is None or key < best_key:
                best, best_key = d, key
        if best is None:
            return None, wake
        return self._start(best, now), now

    def _candidate(self, d: _Drive, now: float) -> tuple[tuple[int, int, float] | None, float]:
        """The drive's claim on the next exchange, or when it will have one."""
        if d.writes:
            self._expire(d.writes, now)
        if d.reads:
            self._expire(d.reads, now)
        if d.active is not None:
            return (d.active.priority, int(d.lagging), d.active.order), now
        if d.writes:
            return (Priority.WRITE, 0, d.writes[0].deadline), now
        if d.reads:
            return (Priority.READ, 0, d.reads[0].deadline), now
        if not d.health.up:
            if d.health.probe_due(now):
                return (Priority.POLL, 0, d.health.next_probe), now
            return None, d.health.next_probe
        if d.polls:
            due = d.polls[0][0]
            if due <= now:
                return (Priority.POLL, 0, due), now
            return None, due
        return None, now + 3600.0

    def _expire(self, queue: deque[Job], now: float) -> None:
        while queue and queue[0].deadline <= now:
            job = queue.popleft()
            self._finish_job(job, JobResult(TimedOut("deadline passed before it was sent")))

    def _start(self, d: _Drive, now: float) -> _Action | None:
        if d.active is not None:
            if now >= d.active.tx.deadline:  # never resend a request past its deadline
                self._complete(d, d.active, TimedOut("deadline passed"), now)
                return None
            return d, d.active.tx.telegram, False
        queue = d.writes or d.reads
        if queue:
            job = queue.popleft()
            tx = PkwTransaction(d.target, job.request, retries=self.retries, deadline=job.deadline)
            d.active = _Active(tx, job.priority, float(next(self._job_seq)), job=job)
            return d, tx.telegram, False
        if not d.health.up:
            return d, d.target.probe(), True
        _, _, poll = heapq.heappop(d.polls)
        spec = poll.spec
        if now - poll.due > spec.every:
            self.events.overrun(d.name)
        # Long enough for the retries and a lagging answer; never the poll's whole
        # interval, which would hold the drive's parameter channel for minutes.
        deadline = now + (self.poll_deadline or 4 * (self.retries + 1) * self.line.timeout)
        tx = PkwTransaction(d.target, spec.request, retries=self.retries, deadline=deadline)
        d.active = _Active(tx, Priority.POLL, poll.due, poll=poll)
        return d, tx.telegram, False

    # ----------------------------------------------------------- doing it

    async def _perform(self, action: _Action) -> None:
        d, telegram, probe = action
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        result = await self.line.exchange(d.target, telegram)
        now = loop.time()
        self.events.exchange(d.name, result, now - t0)
        self._rr = (d.slot + 1) % len(self._drives)
        if self._lagging:
            for other in self._lagging:
                if other is not d:
                    other.lagging = False
            self._lagging.clear()
        self._health(d, result, now)
        if probe:
            if isinstance(result, Reply):
                self._status_from_reply(d, result)
            return
        active = d.active
        if active is None:  # the drive went down and its poll was dropped
            return
        outcome = active.tx.feed(result, now)
        if isinstance(result, Reply) and active.tx.tally.status_word is not None:
            self._set_status(d, active.tx.tally.status_word)
        if outcome is None:
            # A "not yet" or a failed try: the repeat yields to another drive's
            # exchange first, so a lagging or dying drive cannot hold the line.
            d.lagging = active.tx.waiting or isinstance(result, Failure)
            if d.lagging:
                self._lagging.append(d)
            return
        self._complete(d, active, outcome, now)

    def _complete(self, d: _Drive, active: _Active, outcome: Outcome, now: float) -> None:
        d.active = None
        d.lagging = False
        result = self._result(outcome, active, d)
        reading, previous = self._remember(d, active.tx.request, result)
        if active.job is not None:
            if reading is not None:
                self._show_confirmed(d, active.job, reading)
            self._finish_job(active.job, replace(result, previous=previous))
            return
        poll = active.poll
        assert poll is not None
        self.events.job_finished(d.name, _poll_job(d.name, poll.spec, active), result)
        if reading is not None:
            self.snapshot.readings[d.name, poll.spec.parameter, poll.spec.index] = reading
        poll.due = max(poll.due + poll.spec.every, now)
        d.push_poll(poll)

    def _remember(
        self, d: _Drive, request: pkw.PkwRequest, result: JobResult
    ) -> tuple[Reading | None, Reading | None]:
        """(the value the drive just confirmed, the latest one before it).

        An answer that carries the parameter's value - a poll, a read, or a write
        the drive acknowledged by echoing the value it now holds - makes that value
        the parameter's latest, so that the next write's old value is not stale.
        """
        key = (d.name, request.pnu, request.subindex)
        previous = self.snapshot.latest.get(key)
        if result.value is None:
            return None, previous
        reading = Reading(result.value, result.raw, time.time())
        self.snapshot.latest[key] = reading
        return reading, previous

    def _show_confirmed(self, d: _Drive, job: Job, reading: Reading) -> None:
        """A polled parameter shows what a read or an acknowledged write confirmed,
        when the job decoded it as the poll does."""
        for spec in d.spec.polls:
            same = spec.request.pnu == job.request.pnu
            if same and spec.request.subindex == job.request.subindex and spec.fmt == job.fmt:
                self.snapshot.readings[d.name, spec.parameter, spec.index] = reading

    def _result(self, outcome: Outcome, active: _Active, d: _Drive) -> JobResult:
        tally = active.tx.tally
        if not isinstance(outcome, Answered):
            return JobResult(outcome, tally=tally)
        fmt = active.job.fmt if active.job is not None else active.poll.spec.fmt  # type: ignore[union-attr]
        if active.tx.request.is_write and not isinstance(
            outcome.response, pkw.ValueResponse | pkw.TextResponse
        ):
            return JobResult(outcome, tally=tally)
        try:
            raw, value = fmt.value_of(outcome.response)
        except RemoteProtocolError as exc:
            log.warning("%s/%s: %s", self.name, d.name, exc, extra=self._ctx(d))
            return JobResult(TimedOut(f"unusable answer: {exc}"), tally=tally)
        return JobResult(outcome, raw, value, tally)

    def _finish_job(self, job: Job, result: JobResult) -> None:
        self.events.job_finished(job.drive, job, result)
        job.resolve(result)

    def _health(self, d: _Drive, result: ExchangeResult, now: float) -> None:
        if isinstance(result, Reply):
            if d.health.answered():
                log.warning("drive %s answers again", d.name, extra=self._ctx(d))
                self._set_up(d, True)
                d.restart_polls(now)  # not overruns: the drive was away
            elif not self.snapshot.drives[d.name].up:
                self._set_up(d, True)  # back after its line was down
            return
        if result.kind is ErrorKind.PORT:
            return
        if d.health.failed(now):
            log.warning(
                "drive %s is down: %s (probing at back-off)",
                d.name,
                result.kind.value,
                extra=self._ctx(d),
            )
            self._set_up(d, False)
            if d.active is not None and d.active.poll is not None:
                active = d.active
                self._complete(d, active, TimedOut("drive is down"), now)

    def _set_up(self, d: _Drive, up: bool) -> None:
        old = self.snapshot.drives.get(d.name, DriveState())
        self.snapshot.drives[d.name] = DriveState(up, old.status_word, old.status_timestamp)

    def _status_from_reply(self, d: _Drive, reply: Reply) -> None:
        try:
            block = split_block(reply.data, d.target.response_shape(len(reply.data)))
        except RemoteProtocolError:
            return
        if block.pzd:
            self._set_status(d, block.pzd[0])

    def _set_status(self, d: _Drive, word: int) -> None:
        old = self.snapshot.drives.get(d.name, DriveState())
        self.snapshot.drives[d.name] = DriveState(old.up, word, time.time())

    # ------------------------------------------------------- port, idle

    async def _reopen(self) -> None:
        link = self.line.link
        loop = asyncio.get_running_loop()
        self._fail_all("the line's port is not open", loop.time())
        wait = link.next_attempt - loop.time()
        if wait > 0:
            await self._idle(loop.time() + wait)
            if self._stopping or loop.time() < link.next_attempt:
                return  # woken by a new job: it fails at once, the back-off stands
        with contextlib.suppress(PortError):  # reported once by the link's state change
            await link.open()
        if link.is_open:
            for d in self._drives:
                d.restart_polls(loop.time())  # not overruns: the line was away

    def _fail_all(self, reason: str, now: float) -> None:
        """The port is gone: no job waits for it, and nothing in flight is sent later."""
        for d in self._drives:
            if d.active is not None:
                self._complete(d, d.active, LineFailed(reason), now)
            for queue in (d.writes, d.reads):
                while queue:
                    self._finish_job(queue.popleft(), JobResult(LineFailed(reason)))

    async def _idle(self, until: float) -> None:
        loop = asyncio.get_running_loop()
        delay = until - loop.time()
        if delay <= 0:
            return
        self._wake.clear()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._wake.wait(), delay)

    def _on_link_state(self, state: LinkState, error: str | None) -> None:
        up = state is LinkState.OPEN
        self.snapshot.lines[self.name] = up
        if up:
            log.info(
                "line %s: port %s open",
                self.name,
                self.line.link.settings.url,
                extra={"line": self.name},
            )
        elif state is LinkState.FAILED:
            log.warning("line %s: %s", self.name, error, extra={"line": self.name})
            for d in self._drives:  # nobody can tell whether they answer
                self._set_up(d, False)

    def _cancel_all(self, reason: str) -> None:
        for d in self._drives:
            if d.active is not None and d.active.job is not None:
                result = JobResult(Cancelled(reason), tally=d.active.tx.tally)
                self._finish_job(d.active.job, result)
            d.active = None
            for queue in (d.writes, d.reads):
                while queue:
                    self._finish_job(queue.popleft(), JobResult(Cancelled(reason)))

    def _ctx(self, d: _Drive) -> dict[str, str]:
        return {"line": self.name, "drive": d.name}


def _poll_job(drive: str, spec: PollSpec, active: _Active) -> Job:
    return Job(
        drive,
        spec.request,
        JobKind.READ,
        Priority.POLL,
        active.tx.deadline,
        spec.fmt,
        parameter=spec.parameter,
        index=spec.index,
    )
