"""PROFIBUS DP lines under the runner: the slaves cycled in turn, the planner filling each
slave's PKW slot.

Every cycle sends one Data_Exchange (or start-up request) to each slave
(:class:`~pkwbus.master.wires.profibus.cycle.DpMaster`). A slave whose PKW slot is idle
gets the next job the planner gives it alone (:meth:`Planner.next_for`:
writes, on-demand reads, due polls), so the jobs of different slaves run in
parallel and a lagging slave delays only itself. Every answer the slot gets
while it carries the job goes to the planner decoded once, as it is
(:class:`~pkwbus.master.planning.transaction.PkwAnswer`, ``cyclic``): the job's
transaction judges it, as on every bus; a job whose deadline passes ends as
timed out. A job that ended leaves the slot to AK 0.

A DP-V1 slave whose parameters go through PROFIdrive data record 47 (its
carrier a :class:`~pkwbus.master.carriers.RecordCarrier`) has no PKW slot:
the planner's request for it (its polls due together, or a job alone) goes
out as a record transfer, carried by
the cycle between Data_Exchanges, and its response (or why none came) goes to
the planner as the exchange's result.

A slave's health is its state, told to the planner (a slave is up while it is
in data exchange), not counted from missing PKW answers. The PZD of every
Data_Exchange answer gives the drive's status word, without any PKW traffic.
A slave that answers RS, asks for parameters, lost its watchdog or was
power-cycled is parametrised again by its state machine; a job in flight goes
on after that or ends at its deadline. When the port is lost every slave is
offline and starts afresh once the port is back, after listening for other
masters first. Closing sends Global_Control Clear, then closes the port.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from pkwbus.link import Link
from pkwbus.master.carriers import RecordCarrier
from pkwbus.master.planning.answers import ErrorKind, Failure, PkwAnswer, Reply
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.plan import DriveSpec, Send, StatusWord
from pkwbus.master.planning.planner import Planner
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.master.runner import LineRunner
from pkwbus.master.wires.profibus.cycle import DpMaster, SlaveRun
from pkwbus.master.wires.profibus.line import DpLine, ForeignMaster
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus.dp.ppo import PkwSlot, PpoType, SlotAnswer, SlotGarbled, pzd_words
from pkwbus.protocol.profibus.dp.services import Diagnosis
from pkwbus.protocol.profibus.dp.slave import (
    DiagnosisRead,
    DpSlave,
    Failed,
    FailureKind,
    Inputs,
    Restarted,
    RestartReason,
    SlaveEvent,
    SlaveSetup,
    SlaveState,
    StateChanged,
    TransferEnded,
)
from pkwbus.protocol.profibus.dpv1.transfer import RecordRead, TransferEnd
from pkwbus.protocol.profidrive.parameters import RECORD

__all__ = ["CycleWire", "DpEvents", "NoDpEvents", "SlaveSpec"]

log = logging.getLogger(__name__)

_ERROR_KINDS = {
    FailureKind.TIMEOUT: ErrorKind.TIMEOUT,
    FailureKind.GARBLED: ErrorKind.CHECKSUM,
    FailureKind.REFUSED: ErrorKind.UNEXPECTED,
    FailureKind.UNEXPECTED: ErrorKind.UNEXPECTED,
}
DEFAULT_POLL_DEADLINE = 2.0  # seconds: cycles of every slave, a lagging answer included


class DpEvents(Protocol):
    """What a DP line reports beyond the events of every line (the service's metrics)."""

    def slave_state(self, drive: str, state: SlaveState) -> None: ...
    def restarted(self, drive: str, reason: RestartReason) -> None: ...
    def diagnosis(self, drive: str, diagnosis: Diagnosis) -> None: ...


class NoDpEvents:
    def slave_state(self, drive: str, state: SlaveState) -> None:
        pass

    def restarted(self, drive: str, reason: RestartReason) -> None:
        pass

    def diagnosis(self, drive: str, diagnosis: Diagnosis) -> None:
        pass


@dataclass(frozen=True)
class SlaveSpec:
    """One slave: the planner's view of it (name, PKW target, polls) and its DP setup."""

    spec: DriveSpec
    setup: SlaveSetup
    ppo: PpoType

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def record(self) -> RecordCarrier | None:
        """Its carrier where its parameters go through data record 47 (None: through PKW)."""
        carrier = self.spec.carrier
        return carrier if isinstance(carrier, RecordCarrier) else None

    def slot(self) -> PkwSlot | None:
        """Its PKW slot: none on a PPO without PKW, or where parameters go through
        data record 47 (the PKW words then stay at AK 0)."""
        if not self.ppo.has_pkw or self.record is not None:
            return None
        return PkwSlot(self.ppo, self.spec.carrier.dialect)


class CycleWire:
    """The :class:`~pkwbus.master.runner.Wire` of a PROFIBUS DP line."""

    def __init__(
        self,
        line: DpLine,
        drives: Sequence[SlaveSpec],
        *,
        dp_events: DpEvents | None = None,
        listen: float | None = None,
    ) -> None:
        self.line = line
        self.drives = list(drives)
        self.dp_events: DpEvents = dp_events or NoDpEvents()
        self.listen = listen
        self.master = DpMaster(
            line, [(d.setup, d.slot()) for d in drives], on_event=self._on_event,
            feed=self._feed, on_answered=self._on_answered,
        )  # fmt: skip
        self._runner: LineRunner | None = None
        self._names = {d.setup.address: d.name for d in drives}
        self._specs_by_name = {d.name: d.setup.address for d in drives}
        self._specs = {d.setup.address: d for d in drives}
        self._sends: dict[str, Send] = {}
        self._garbled: dict[str, SlotGarbled] = {}  # this exchange's unreadable PKW answer
        self._unreadable: set[str] = set()  # slaves whose PKW answers cannot be read
        for d in drives:
            self.dp_events.slave_state(d.name, SlaveState.OFFLINE)

    @property
    def link(self) -> Link:
        return self.line.link

    @property
    def runner(self) -> LineRunner:
        runner = self._runner
        assert runner is not None  # attached at the runner's construction
        return runner

    def planner_for(
        self,
        drives: Sequence[DriveSpec],
        retries: int,
        policy: HealthPolicy | None,
        poll_deadline: float | None,
    ) -> Planner:
        return Planner(
            drives, poll_deadline=poll_deadline or DEFAULT_POLL_DEADLINE, retries=retries,
            policy=policy,
        )  # fmt: skip

    def attach(self, runner: LineRunner) -> None:
        self._runner = runner

    async def started(self) -> None:
        """Listen before sending; another master heard gives the port up at back-off."""
        try:
            await self.line.listen(self.listen)
        except ForeignMaster as exc:
            self._foreign(exc)

    async def carry(self) -> float | None:
        try:
            await self.master.cycle()
        except ForeignMaster as exc:
            self._foreign(exc)
        return None

    def lost(self) -> None:
        """Every slave offline and started afresh; every job in flight has ended."""
        self._sends.clear()
        self.line.foreign = None
        for address, run in self.master.runs.items():
            if run.slave.state is not SlaveState.OFFLINE:
                self.dp_events.slave_state(self._names[address], SlaveState.OFFLINE)
            spec = self._specs[address]
            self.master.runs[address] = SlaveRun(DpSlave(spec.setup), spec.slot())

    async def close(self) -> None:
        await self.master.stop()  # Global_Control Clear to every slave, then close

    # ------------------------------------------------------------ internals

    def _foreign(self, exc: ForeignMaster) -> None:
        log.error("line %s: %s", self.runner.name, exc, extra={"line": self.runner.name})
        self.link.abort(str(exc))

    def _feed(self, run: SlaveRun, now: float) -> None:
        """Before the slave's turn in a cycle: end its job when the planner has ended it or
        its deadline has passed; fill an idle slot with the planner's next job for that
        slave alone."""
        name = self._names[run.address]
        slot, slave, runner = run.slot, run.slave, self.runner
        if self._specs[run.address].record is not None:
            self._feed_record(name, run, now)
            return
        if slot is None:
            return
        planner = runner.planner
        if slot.busy:
            send, tx = self._sends.get(name), planner.active(name)
            if send is None or not isinstance(tx, PkwTransaction) or tx.request is not slot.request:
                self._sends.pop(name, None)  # ended meanwhile (the line stopped, say)
                slot.finish()
            elif now >= tx.deadline:
                detail = f"no matching answer within the deadline ({slot.cycles} cycles)"
                self._done(name, send, Failure(ErrorKind.TIMEOUT, detail), now)
            if slot.busy:
                return
        send = self._next(name, slave, now)
        tx = planner.active(name) if send is not None else None
        if send is None or not isinstance(tx, PkwTransaction):  # (next_for gave its Send)
            return
        slot.submit(tx.request)
        self._sends[name] = send

    def _next(self, name: str, slave: DpSlave, now: float) -> Send | None:
        """The planner's next request for the slave alone; None, and its jobs past their
        deadline ended, while nothing can go out to it."""
        planner, runner = self.runner.planner, self.runner
        if slave.state is not SlaveState.DATA_EXCHANGE or slave.waiting:
            planner.expire_queued(name, now)  # nothing can go out: they end at deadline
            runner.batch()
            return None
        send = planner.next_for(name, now)
        runner.batch()
        return send

    def _feed_record(self, name: str, run: SlaveRun, now: float) -> None:
        """A DP-V1 slave whose parameters go through data record 47: with no transfer in
        progress, the planner's next request for it (polls due together, or a job alone)
        starts one; its end comes back as a TransferEnded."""
        slave, runner = run.slave, self.runner
        if name in self._sends:
            return  # its transfer is in progress: it ends on its own (response timeout)
        planner = runner.planner
        send = self._next(name, slave, now)
        if send is None:
            return
        record = self._specs[run.address].record
        assert record is not None
        try:
            slave.start_transfer(record.slot, RECORD, send.telegram, now)
        except LocalProtocolError as exc:  # a record larger than the slave takes, say
            planner.exchanged(send, Failure(ErrorKind.UNEXPECTED, str(exc)), now)
            runner.batch()
            return
        self._sends[name] = send

    def _transfer_ended(self, name: str, address: int, end: TransferEnd, now: float) -> None:
        """A record transfer is over: its response, or why none came, to the planner."""
        send = self._sends.pop(name, None)
        if send is None:
            return
        result: Reply | Failure
        if isinstance(end, RecordRead):
            result = Reply(address, end.data, self.master.answer_time)
        else:
            kind = ErrorKind.TIMEOUT if end.timed_out else ErrorKind.UNEXPECTED
            result = Failure(kind, end.why)
        self.runner.planner.exchanged(send, result, now)

    def _on_event(self, address: int, event: SlaveEvent | SlotAnswer | SlotGarbled) -> None:
        name = self._names[address]
        runner, master = self.runner, self.master
        now = asyncio.get_running_loop().time()
        # The line was busy for as long as the exchange held it (its idle time before the
        # request included); the answer took the time from the request written to it.
        if isinstance(event, Inputs):
            garbled = self._garbled.pop(name, None)
            result: Reply | Failure = Reply(address, event.data, master.answer_time)
            if garbled is not None and garbled.request is None:  # no job counts it
                result = Failure(ErrorKind.UNEXPECTED, garbled.why)
            runner.exchanged(name, result, master.exchange_time)
            self._readable(name, garbled)
            self._status(name, address, event.data)
        elif isinstance(event, SlotGarbled):
            self._garbled[name] = event
            send = self._sends.get(name)
            if event.request is not None and send is not None:
                unreadable = PkwAnswer(None, b"", None, None, master.answer_time, cyclic=True,
                                       why=event.why)  # fmt: skip
                self._done(name, send, unreadable, now)
        elif isinstance(event, Failed):
            failure = Failure(_ERROR_KINDS[event.kind], event.detail)
            runner.exchanged(name, failure, master.exchange_time)
        elif isinstance(event, StateChanged):
            self._state(name, event, now)
        elif isinstance(event, Restarted):
            self.dp_events.restarted(name, event.reason)
            log.warning(
                "drive %s: parametrised again (%s)", name, event.reason, extra={"drive": name}
            )
        elif isinstance(event, DiagnosisRead):
            self.dp_events.diagnosis(name, event.diagnosis)
        elif isinstance(event, SlotAnswer):
            self._answer(name, event, now)
        elif isinstance(event, TransferEnded):
            self._transfer_ended(name, address, event.end, now)
        runner.batch()

    def _answer(self, name: str, event: SlotAnswer, now: float) -> None:
        """The slot's answer, decoded once, to the job it carries: the job judges it (its
        status word went out with the cycle's Inputs)."""
        send = self._sends.get(name)
        if send is None:
            return
        answer = PkwAnswer(
            event.response, b"", None, None, self.master.answer_time, cyclic=True,
            earlier=event.earlier,
        )  # fmt: skip
        self._done(name, send, answer, now)

    def _done(self, name: str, send: Send, result: PkwAnswer | Failure, now: float) -> None:
        """Give ``result`` to the job in the slave's slot; an ended job leaves the slot."""
        planner = self.runner.planner
        tx = planner.active(name)
        planner.exchanged(send, result, now)
        if tx is None or tx.outcome is not None or planner.active(name) is not tx:
            self._sends.pop(name, None)
            run = self.master.runs[self._specs_by_name[name]]
            if run.slot is not None:
                run.slot.finish()

    def _readable(self, name: str, garbled: SlotGarbled | None) -> None:
        """Tell once when a slave's PKW answers stop being readable, and when they are
        readable again (the counts are the telegram errors of kind ``unexpected``)."""
        ctx = {"line": self.runner.name, "drive": name}
        if garbled is not None and name not in self._unreadable:
            self._unreadable.add(name)
            log.warning(
                "drive %s: %s: is the drive set to this PPO and dialect? Its parameter"
                " jobs end unanswered until it is", name, garbled.why, extra=ctx,
            )  # fmt: skip
        elif garbled is None and name in self._unreadable:
            self._unreadable.discard(name)
            log.info("drive %s: its PKW answers can be read again", name, extra=ctx)

    def _on_answered(self, address: int, answer: float, took: float) -> None:
        """A start-up request (diagnosis, Set_Prm, Chk_Cfg) answered: a telegram that held
        the line, like a Data_Exchange."""
        self.runner.exchanged(self._names[address], Reply(address, b"", answer), took)

    def _state(self, name: str, event: StateChanged, now: float) -> None:
        self.dp_events.slave_state(name, event.new)
        planner = self.runner.planner
        ctx = {"line": self.runner.name, "drive": name}
        if event.new is SlaveState.DATA_EXCHANGE:
            log.info("drive %s: in data exchange", name, extra=ctx)
            planner.told_health(name, True, "", now)
        elif event.old is SlaveState.DATA_EXCHANGE:
            planner.told_health(name, False, f"left data exchange ({event.new})", now)
        elif event.new is SlaveState.LOCKED:
            log.error(
                "drive %s: owned by another master: pkwbus does not parametrise it", name,
                extra=ctx,
            )  # fmt: skip

    def _status(self, name: str, address: int, data: bytes) -> None:
        """The PPO-read's PZD: status word (ZSW) and main actual value (HIW)."""
        words = pzd_words(self._specs[address].ppo, data)
        if words:
            mav = words[1] if len(words) > 1 else None
            self.runner.tell([StatusWord(name, words[0], mav)])
