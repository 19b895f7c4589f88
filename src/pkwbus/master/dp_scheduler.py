"""The runner of one PROFIBUS DP line in the service: its slaves cycled in turn, the
planner filling each slave's PKW slot, the events recorded as for FC and USS.

Every cycle sends one Data_Exchange (or start-up request) to each slave
(:class:`~pkwbus.master.dp_master.DpMaster`). A slave whose PKW slot is idle
gets the next job the planner gives it alone (:meth:`Planner.next_for`:
writes, on-demand reads, due polls), so the jobs of different slaves run in
parallel and a lagging slave delays only itself. A slave's answer that
matches its job goes to the planner as the job's reply; a job whose deadline
passes ends as timed out. What the planner's events mean (values into the
snapshot, job futures, metrics) is :mod:`pkwbus.master.record`'s.

A slave is up while it is in data exchange. The PZD of every Data_Exchange
answer gives the drive's status word, without any PKW traffic. A slave that
answers RS, asks for parameters, lost its watchdog or was power-cycled is
parametrised again by its state machine; a job in flight goes on after that
or ends at its deadline. When the port is lost every slave is offline, every
job in flight ends, and the line starts again (listening before it sends)
once the port is back. Stopping sends Global_Control Clear, then closes.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from pkwbus.link import PortError
from pkwbus.master.dp_line import DpLine, ForeignMaster
from pkwbus.master.dp_master import DpMaster, SlaveRun
from pkwbus.master.health import HealthPolicy
from pkwbus.master.jobs import Job
from pkwbus.master.plan import DriveSpec, Event, HealthChanged, Send, StatusWord
from pkwbus.master.planner import Planner
from pkwbus.master.record import LineEvents, LineRecord, NoEvents
from pkwbus.master.snapshot import DriveState, Snapshot
from pkwbus.master.transaction import ErrorKind, Failure, PkwAnswer, Reply
from pkwbus.protocol.dp_slave import (
    DiagnosisRead,
    DpSlave,
    Failed,
    FailureKind,
    Inputs,
    Restarted,
    RestartReason,
    SlaveSetup,
    SlaveState,
    StateChanged,
)
from pkwbus.protocol.dp_slave import Event as SlaveEvent
from pkwbus.protocol.ppo import JobDone, JobExpired, JobResult, PkwSlot, PpoType

__all__ = ["DpDriveSpec", "DpEvents", "DpScheduler", "NoDpEvents"]

log = logging.getLogger(__name__)

# The planner's own health count never takes a DP slave down: its state machine does.
_NEVER_DOWN = HealthPolicy(down_after=1 << 30)
_ERROR_KINDS = {
    FailureKind.TIMEOUT: ErrorKind.TIMEOUT,
    FailureKind.GARBLED: ErrorKind.CHECKSUM,
    FailureKind.REFUSED: ErrorKind.UNEXPECTED,
    FailureKind.UNEXPECTED: ErrorKind.UNEXPECTED,
}


class DpEvents(Protocol):
    """What a DP line reports beyond the events of every line (the service's metrics)."""

    def slave_state(self, drive: str, state: SlaveState) -> None: ...
    def restarted(self, drive: str, reason: RestartReason) -> None: ...
    def diagnosis(self, drive: str, flags: frozenset[str]) -> None: ...


class NoDpEvents:
    def slave_state(self, drive: str, state: SlaveState) -> None:
        pass

    def restarted(self, drive: str, reason: RestartReason) -> None:
        pass

    def diagnosis(self, drive: str, flags: frozenset[str]) -> None:
        pass


@dataclass(frozen=True)
class DpDriveSpec:
    """One slave: the planner's view of it (name, PKW target, polls) and its DP setup."""

    spec: DriveSpec
    setup: SlaveSetup
    ppo: PpoType

    @property
    def name(self) -> str:
        return self.spec.name

    def slot(self) -> PkwSlot | None:
        return PkwSlot(self.ppo, self.spec.target.dialect) if self.ppo.has_pkw else None


class DpScheduler:
    """Runs one DP line: the service's task for it."""

    def __init__(
        self,
        name: str,
        line: DpLine,
        drives: Sequence[DpDriveSpec],
        *,
        snapshot: Snapshot | None = None,
        events: LineEvents | None = None,
        dp_events: DpEvents | None = None,
        poll_deadline: float = 2.0,
        retries: int = 2,
        listen: float | None = None,
    ) -> None:
        self.name = name
        self.line = line
        self.drives = list(drives)
        self.snapshot = snapshot if snapshot is not None else Snapshot()
        self.events: LineEvents = events or NoEvents()
        self.dp_events: DpEvents = dp_events or NoDpEvents()
        self.record = LineRecord(name, [d.spec for d in drives], self.snapshot, self.events)
        self.planner = Planner(
            [d.spec for d in drives], poll_deadline=poll_deadline, retries=retries,
            policy=_NEVER_DOWN, stale_answers=False,  # the PKW slot waits for AK 0 instead
        )  # fmt: skip
        self.master = DpMaster(
            line, [(d.setup, d.slot()) for d in drives], on_event=self._on_event,
            feed=self._feed, on_answered=self._on_answered,
        )  # fmt: skip
        self.listen = listen
        self._names = {d.setup.address: d.name for d in drives}
        self._specs = {d.setup.address: d for d in drives}
        self._sends: dict[str, Send] = {}
        self._stopping = False
        self._wake = asyncio.Event()
        for d in drives:
            self.dp_events.slave_state(d.name, SlaveState.OFFLINE)

    # ------------------------------------------------------------ the service's

    def submit(self, job: Job) -> None:
        """Queue a write or on-demand read; its future gets the result."""
        self.planner.submit(job, asyncio.get_running_loop().time())
        self._flush()

    def stop(self) -> None:
        """Take no new jobs; the cycle in progress ends, then :meth:`run` returns."""
        self._stopping = True
        self._wake.set()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            while not self._stopping:
                if not self.line.is_open:
                    await self._start(loop)
                    continue
                try:
                    await self.master.cycle()
                except PortError as exc:
                    self._port_lost(str(exc), loop.time())
                except ForeignMaster as exc:
                    log.error("line %s: %s", self.name, exc, extra={"line": self.name})
                    self._port_lost("another master is active on the line", loop.time())
                    await self.line.close()
                    self.line.foreign = None
                    self.line.reconnect.failed(str(exc), loop.time())
                except Exception as exc:  # a line never stops: report, reopen, go on
                    log.exception(
                        "line %s: unexpected error, reopening its port",
                        self.name,
                        extra={"line": self.name},
                    )
                    self._port_lost(f"unexpected error: {exc!r}", loop.time())
                    await self.line.close()
                self._flush()
        finally:
            self.planner.stop("the service is stopping")
            self._flush()
            with contextlib.suppress(Exception):
                await self.master.stop()  # Global_Control Clear to every slave, then close
            self.snapshot.lines[self.name] = False

    # ------------------------------------------------------------ start and loss

    async def _start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Open the port and listen before sending; at back-off when that fails."""
        reconnect = self.line.reconnect
        wait = reconnect.wait(loop.time())
        if wait > 0:
            self._wake.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._wake.wait(), wait)
            return
        try:
            await self.master.start(listen=self.listen)
        except PortError as exc:
            log.warning("line %s: %s", self.name, exc, extra={"line": self.name})
            return
        except ForeignMaster as exc:
            log.error("line %s: %s", self.name, exc, extra={"line": self.name})
            self.line.foreign = None
            reconnect.failed(str(exc), loop.time())
            return
        ctx = {"line": self.name}
        log.info("line %s: port %s open", self.name, self.line.settings.url, extra=ctx)
        self.snapshot.lines[self.name] = True
        self.planner.line_up(loop.time())

    def _port_lost(self, reason: str, now: float) -> None:
        """Every slave offline and started afresh; every job in flight ends."""
        log.warning("line %s: %s", self.name, reason, extra={"line": self.name})
        self.snapshot.lines[self.name] = False
        self.planner.line_down(now)
        self._sends.clear()
        for address, run in self.master.runs.items():
            name = self._names[address]
            if run.slave.state is not SlaveState.OFFLINE:
                self.dp_events.slave_state(name, SlaveState.OFFLINE)
            if self.snapshot.drives.get(name, DriveState()).up:
                self._record([HealthChanged(name, False, "the line's port is lost")])
            spec = self._specs[address]
            self.master.runs[address] = SlaveRun(DpSlave(spec.setup), spec.slot())
        self._flush()

    # ------------------------------------------------------------ the master's hooks

    def _feed(self, run: SlaveRun, now: float) -> None:
        """Fill an idle slot with the planner's next job for that slave alone."""
        name = self._names[run.address]
        slot = run.slot
        slave = run.slave
        if slot is None:
            return
        if slave.state is not SlaveState.DATA_EXCHANGE or slave.waiting:
            self.planner.expire_queued(name, now)  # nothing can go out: they end at deadline
            self._flush()
            return
        send = self.planner.next_for(name, now)
        self._flush()
        if send is None:
            return
        tx = self.planner.active(name)
        if tx is None:  # cannot happen: next_for gave a Send of its transaction
            return
        slot.submit(tx.request, tx.deadline)
        self._sends[name] = send

    def _on_event(self, address: int, event: SlaveEvent | JobResult) -> None:
        name = self._names[address]
        now = asyncio.get_running_loop().time()
        # The line was busy for as long as the exchange held it (its idle time before the
        # request included); the answer took the time from the request written to it.
        took = self.master.exchange_time
        if isinstance(event, Inputs):
            reply = Reply(address, event.data, self.master.answer_time)
            self.events.exchange(name, reply, took)
            self._status(name, address, event.data)
        elif isinstance(event, Failed):
            failure = Failure(_ERROR_KINDS[event.kind], event.detail)
            self.events.exchange(name, failure, took)
        elif isinstance(event, StateChanged):
            self._state(name, event, now)
        elif isinstance(event, Restarted):
            self.dp_events.restarted(name, event.reason)
            log.warning(
                "drive %s: parametrised again (%s)", name, event.reason, extra={"drive": name}
            )
        elif isinstance(event, DiagnosisRead):
            if event.diagnosis.flags:
                self.dp_events.diagnosis(name, event.diagnosis.flags)
        elif isinstance(event, JobDone):
            send = self._sends.pop(name, None)
            if send is not None:  # the answer as the slot decoded it, with its PZD
                pzd = event.read.pzd if event.read is not None else ()
                answer = PkwAnswer(
                    event.response, b"", pzd[0] if pzd else None,
                    pzd[1] if len(pzd) > 1 else None, self.master.answer_time,
                )  # fmt: skip
                self.planner.exchanged(send, answer, now)
        elif isinstance(event, JobExpired):
            send = self._sends.pop(name, None)
            if send is not None:
                detail = f"no matching answer within the deadline ({event.cycles} cycles)"
                self.planner.exchanged(send, Failure(ErrorKind.TIMEOUT, detail), now)
        self._flush()

    def _on_answered(self, address: int, answer: float, took: float) -> None:
        """A start-up request (diagnosis, Set_Prm, Chk_Cfg) answered: a telegram that held
        the line, like a Data_Exchange."""
        self.events.exchange(self._names[address], Reply(address, b"", answer), took)

    def _state(self, name: str, event: StateChanged, now: float) -> None:
        self.dp_events.slave_state(name, event.new)
        ctx = {"line": self.name, "drive": name}
        if event.new is SlaveState.DATA_EXCHANGE:
            log.info("drive %s: in data exchange", name, extra=ctx)
            self._record([HealthChanged(name, True, "")])
            self.planner.drive_back(name, now)
        elif event.old is SlaveState.DATA_EXCHANGE:
            self._record([HealthChanged(name, False, f"left data exchange ({event.new})")])
        elif event.new is SlaveState.LOCKED:
            log.error(
                "drive %s: owned by another master: pkwbus does not parametrise it", name,
                extra=ctx,
            )  # fmt: skip

    def _status(self, name: str, address: int, data: bytes) -> None:
        """The PPO-read's PZD: status word (ZSW) and main actual value (HIW)."""
        spec = self._specs[address]
        at = 2 * spec.ppo.pkw_words
        if len(data) >= at + 2:
            word = int.from_bytes(data[at : at + 2], "big")
            mav = int.from_bytes(data[at + 2 : at + 4], "big") if len(data) >= at + 4 else None
            old = self.snapshot.drives.get(name, DriveState())
            self.snapshot.drives[name] = DriveState(old.up, word, time.time(), mav)

    # ------------------------------------------------------------ events

    def _flush(self) -> None:
        # A DP slave's health and status word come from its state and its PZD, not
        # from the planner's view of PKW answers.
        if self.planner.events:
            events = self.planner.take_events()
            self._record([e for e in events if not isinstance(e, HealthChanged | StatusWord)])

    def _record(self, events: list[Event]) -> None:
        if events:
            self.record.apply(events)
