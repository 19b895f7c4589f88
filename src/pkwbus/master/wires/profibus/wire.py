"""PROFIBUS DP lines under the runner: the slaves cycled in turn, the planner filling each
slave's PKW slot. Pure calls, holding no runner and no port
(:class:`~pkwbus.master.runner.Wire`).

Every cycle sends one Data_Exchange (or start-up request) to each slave
(:class:`~pkwbus.master.wires.profibus.cycle.SlaveCycle`). A slave whose PKW
slot is idle gets the next job the planner gives it alone
(:meth:`Planner.next_for`: writes, on-demand reads, due polls), so the jobs of
different slaves run in parallel and a lagging slave delays only itself.
Every PPO-read that comes while the slot carries the job goes to the planner
as it came (a :class:`~pkwbus.master.planning.answers.Reply`), its PKW words
decoded once by the slot and taken by the job's carrier
(:class:`~pkwbus.master.carriers.SlotCarrier`): the job's transaction judges
it, as on every bus; a job whose deadline passes ends as timed out. A job
that ended leaves the slot to AK 0.

A DP-V1 slave whose parameters go through PROFIdrive data record 47 (its
carrier a :class:`~pkwbus.master.carriers.RecordCarrier`) has no PKW slot:
the planner's request for it (its polls due together, or a job alone) goes
out as a record transfer, carried by the cycle between Data_Exchanges, and
its response (or why none came) goes to the planner as the exchange's result.

A slave's health is its state, told to the planner (a slave is up while it
is in data exchange, down when it leaves it or, offline, answers none of a
request's repeats), not counted from missing PKW answers. The PZD of every
Data_Exchange answer gives the drive's status word, without any PKW traffic.
A slave that answers RS, asks for parameters, lost its watchdog or was
power-cycled is parametrised again by its state machine; a job in flight goes
on after that or ends at its deadline. When the port is lost every slave is
offline and starts afresh once the port is back (the port listens for other
masters first, and forgets one it heard when it fails; the port of a line's
master, made with ``clear_on_close``, sends Global_Control Clear before it
closes).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

from pkwbus.master.carriers import RecordCarrier, SlotCarrier
from pkwbus.master.events import (
    Event,
    Exchanged,
    SlaveDiagnosed,
    SlaveRestarted,
    SlaveSilent,
    SlaveStateChanged,
)
from pkwbus.master.planning.answers import ErrorKind, Failure, Reply
from pkwbus.master.planning.plan import DriveSpec, Idle, StatusWord
from pkwbus.master.planning.planner import Planner
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.master.wires.profibus.cycle import (
    IDLE_STEP,
    CycleEvent,
    SlaveCycle,
    SlaveRun,
    StartupAnswered,
)
from pkwbus.master.wires.profibus.refusal import CONFIGURATION, refusal
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus.dp.ppo import PkwSlot, PpoType, SlotAnswer, SlotGarbled, pzd_words
from pkwbus.protocol.profibus.dp.services import Diagnosis
from pkwbus.protocol.profibus.dp.slave import (
    Answer,
    DiagnosisRead,
    Failed,
    FailureKind,
    Inputs,
    Restarted,
    SlaveSetup,
    SlaveState,
    StateChanged,
    TransferEnded,
)
from pkwbus.protocol.profibus.dpv1.transfer import RecordRead
from pkwbus.protocol.profibus.fdl import DataFrame
from pkwbus.protocol.profidrive.parameters import RECORD

__all__ = ["DEFAULT_POLL_DEADLINE", "CycleWire", "SlaveSpec"]

log = logging.getLogger(__name__)

_ERROR_KINDS = {
    FailureKind.TIMEOUT: ErrorKind.TIMEOUT,
    FailureKind.GARBLED: ErrorKind.CHECKSUM,
    FailureKind.REFUSED: ErrorKind.UNEXPECTED,
    FailureKind.UNEXPECTED: ErrorKind.UNEXPECTED,
}
DEFAULT_POLL_DEADLINE = 2.0  # seconds: cycles of every slave, a lagging answer included
RESTARTS_SAID_EVERY = 60.0  # seconds between log lines of a slave parametrised over and over


@dataclass(frozen=True)
class SlaveSpec:
    """One slave: the planner's view of it (name, carrier, polls) and its DP setup."""

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
        """Its PKW slot afresh, its carrier's: none on a PPO without PKW, or where
        parameters go through data record 47 (the PKW words then stay at AK 0)."""
        carrier = self.spec.carrier
        if not self.ppo.has_pkw or not isinstance(carrier, SlotCarrier):
            return None
        return carrier.new_slot()


class CycleWire:
    """The :class:`~pkwbus.master.runner.Wire` of a PROFIBUS DP line."""

    def __init__(self, drives: Sequence[SlaveSpec], *, name: str = "") -> None:
        self.name = name  # the line's, for the log
        self.drives = list(drives)
        self.cycle = SlaveCycle([(d.setup, d.slot()) for d in drives])
        self._names = {d.setup.address: d.name for d in drives}
        self._specs = {d.setup.address: d for d in drives}
        self._events: list[Event] = [SlaveStateChanged(d.name, SlaveState.OFFLINE) for d in drives]
        self._garbled: dict[str, SlotGarbled] = {}  # this exchange's unreadable PKW answer
        self._unreadable: set[str] = set()  # slaves whose PKW answers cannot be read
        # Slaves parametrised again and not in data exchange since: when it was last said in
        # the log, and how often since (one that refuses its parameters: every cycle).
        self._restarts: dict[str, tuple[float, int]] = {}
        self._told: set[str] = set()  # slaves whose health was told: not down from the start
        self._diagnoses: dict[str, Diagnosis] = {}  # each slave's latest

    def poll_deadline(self, retries: int) -> float:
        return DEFAULT_POLL_DEADLINE

    def transmit(self, planner: Planner, now: float) -> DataFrame | Idle:
        frame = self.cycle.transmit(now, lambda run, at: self._before(planner, run, at))
        self._take(planner, now, 0.0, 0.0)
        return frame if frame is not None else Idle(now + IDLE_STEP)

    def received(
        self, planner: Planner, request: DataFrame, answer: Answer, now: float, busy: float,
        answered: float,
    ) -> None:  # fmt: skip
        self.cycle.received(answer, now)
        self._take(planner, now, busy, answered)

    def lost(self) -> None:
        """Every slave offline and started afresh; every job in flight has ended."""
        for address, run in self.cycle.runs.items():
            if run.slave.state is not SlaveState.OFFLINE:
                self._events.append(SlaveStateChanged(self._names[address], SlaveState.OFFLINE))
        self.cycle.restart([(d.setup, d.slot()) for d in self.drives])

    def leave_out(self, planner: Planner, drive: str, out: bool, now: float) -> None:
        """A drive in maintenance: its slave is sent nothing, not even a Data_Exchange, and
        the job its PKW slot or record transfer carried ends (no answer can come); out of
        maintenance it is parametrised afresh."""
        spec = next((d for d in self.drives if d.name == drive), None)
        if spec is None:
            return
        run = self.cycle.runs.get(spec.setup.address)
        if out and run is not None and run.slave.state is not SlaveState.OFFLINE:
            self._events.append(SlaveStateChanged(drive, SlaveState.OFFLINE))  # sent nothing
        self.cycle.leave_out(spec.setup, None if out else spec.slot(), out)
        send = planner.sending(drive)
        if out and send is not None and planner.drive(drive).busy:
            planner.exchanged(send, Failure(ErrorKind.TIMEOUT, "left out: in maintenance"), now)

    def take_events(self) -> list[Event]:
        events, self._events = self._events, []
        return events

    # ------------------------------------------------------------ internals

    def _before(self, planner: Planner, run: SlaveRun, now: float) -> None:
        """Before the slave's turn in a cycle: end its job when the planner has ended it or
        its deadline has passed; fill an idle slot with the planner's next job for that
        slave alone."""
        name = self._names[run.address]
        slot, slave = run.slot, run.slave
        if self._specs[run.address].record is not None:
            self._before_record(planner, name, run, now)
            return
        if slot is None:
            return
        if slot.busy:
            send, tx = planner.sending(name), planner.active(name)
            if send is None or not isinstance(tx, PkwTransaction) or tx.request is not slot.request:
                slot.finish()  # ended meanwhile (the line stopped, say)
            elif now >= tx.deadline:
                detail = f"no matching answer within the deadline ({slot.cycles} cycles)"
                self._done(planner, run, Failure(ErrorKind.TIMEOUT, detail), now)
            if slot.busy:
                return
        if self._next(planner, name, slave.state, slave.waiting, now):
            tx = planner.active(name)
            if isinstance(tx, PkwTransaction):
                slot.submit(tx.request, tx.telegram)  # encoded once, by its carrier

    def _next(
        self, planner: Planner, name: str, state: SlaveState, waiting: bool, now: float
    ) -> bool:
        """Whether the planner gave the slave its next request; while nothing can go out to
        it, its jobs past their deadline end."""
        if state is not SlaveState.DATA_EXCHANGE or waiting:
            planner.expire_queued(name, now)  # nothing can go out: they end at deadline
            return False
        return planner.next_for(name, now) is not None

    def _before_record(self, planner: Planner, name: str, run: SlaveRun, now: float) -> None:
        """A DP-V1 slave whose parameters go through data record 47: with no transfer in
        progress, the planner's next request for it (polls due together, or a job alone)
        starts one; its end comes back as a TransferEnded."""
        if planner.drive(name).busy:
            return  # its transfer is in progress: it ends on its own (response timeout)
        slave = run.slave
        if not self._next(planner, name, slave.state, slave.waiting, now):
            return
        send = planner.sending(name)
        record = self._specs[run.address].record
        assert send is not None and record is not None
        try:
            slave.start_transfer(record.slot, RECORD, send.telegram, now)
        except LocalProtocolError as exc:  # a record larger than the slave takes, say
            planner.exchanged(send, Failure(ErrorKind.UNEXPECTED, str(exc)), now)

    def _take(self, planner: Planner, now: float, busy: float, answered: float) -> None:
        """What the cycle told, in order: to the planner, and on the stream."""
        for run, event in self.cycle.take_events():
            self._on(planner, run, event, now, busy, answered)

    def _on(
        self, planner: Planner, run: SlaveRun, event: CycleEvent, now: float, busy: float,
        answered: float,
    ) -> None:  # fmt: skip
        address = run.address
        name = self._names[address]
        events = self._events
        if isinstance(event, Inputs):
            garbled = self._garbled.pop(name, None)
            error = None
            if garbled is not None and garbled.request is None:  # no job counts it
                error = ErrorKind.UNEXPECTED
            events.append(Exchanged(name, error, busy, answered))
            self._readable(name, garbled)
            slot = run.slot  # a slot cut the PZD as it read the PPO; else they are cut here
            if slot is None:
                words = pzd_words(self._specs[address].ppo, event.data)
            else:
                words = slot.update.pzd if slot.update is not None else ()
            if words:
                events.append(StatusWord(name, words[0], words[1] if len(words) > 1 else None))
        elif isinstance(event, SlotGarbled):
            self._garbled[name] = event
            if event.request is not None and planner.sending(name) is not None:
                self._read(planner, run, now, answered)
        elif isinstance(event, StartupAnswered):
            events.append(Exchanged(name, None, busy, answered))
        elif isinstance(event, Failed):
            events.append(Exchanged(name, _ERROR_KINDS[event.kind], busy))
            slave = run.slave
            silent = event.kind is FailureKind.TIMEOUT and not slave.waiting
            if silent and slave.state is SlaveState.OFFLINE:  # every repeat went unanswered
                events.append(SlaveSilent(name, event.detail))
                if planner.drive(name).shown_up or name not in self._told:  # never answered
                    self._tell(planner, name, False, "does not answer", now)
        elif isinstance(event, StateChanged):
            self._state(planner, name, event, now)
        elif isinstance(event, Restarted):
            events.append(SlaveRestarted(name, event.reason))
            self._restarted(name, event.reason, now)
        elif isinstance(event, DiagnosisRead):
            events.append(SlaveDiagnosed(name, event.diagnosis))
            self._diagnoses[name] = event.diagnosis
        elif isinstance(event, SlotAnswer):
            if planner.sending(name) is not None:
                self._read(planner, run, now, answered)
        elif isinstance(event, TransferEnded):
            self._transfer_ended(planner, name, address, event, now, answered)

    def _transfer_ended(
        self, planner: Planner, name: str, address: int, event: TransferEnded, now: float,
        answered: float,
    ) -> None:  # fmt: skip
        """A record transfer is over: its response, or why none came, to the planner."""
        send = planner.sending(name)
        if send is None or not planner.drive(name).busy:
            return
        end = event.end
        result: Reply | Failure
        if isinstance(end, RecordRead):
            result = Reply(address, end.data, answered)
        else:
            kind = ErrorKind.TIMEOUT if end.timed_out else ErrorKind.UNEXPECTED
            result = Failure(kind, end.why)
        planner.exchanged(send, result, now)

    def _read(self, planner: Planner, run: SlaveRun, now: float, answered: float) -> None:
        """The PPO-read the slot just took, as it came, to the job it carries."""
        assert run.slot is not None and run.slot.update is not None
        self._done(planner, run, Reply(run.address, run.slot.update.inputs, answered), now)

    def _done(self, planner: Planner, run: SlaveRun, result: Reply | Failure, now: float) -> None:
        """Give ``result`` to the job in the slave's slot; an ended job leaves the slot."""
        name = self._names[run.address]
        send, tx = planner.sending(name), planner.active(name)
        if send is None:
            return
        planner.exchanged(send, result, now)
        ended = tx is None or tx.outcome is not None or planner.active(name) is not tx
        if ended and run.slot is not None:
            run.slot.finish()

    def _readable(self, name: str, garbled: SlotGarbled | None) -> None:
        """Tell once when a slave's PKW answers stop being readable, and when they are
        readable again (the counts are the telegram errors of kind ``unexpected``)."""
        ctx = {"line": self.name, "drive": name}
        if garbled is not None and name not in self._unreadable:
            self._unreadable.add(name)
            log.warning(
                "drive %s: %s: is the drive set to this PPO and dialect? Its parameter"
                " jobs end unanswered until it is", name, garbled.why, extra=ctx,
            )  # fmt: skip
        elif garbled is None and name in self._unreadable:
            self._unreadable.discard(name)
            log.info("drive %s: its PKW answers can be read again", name, extra=ctx)

    def _restarted(self, name: str, reason: str, now: float) -> None:
        """A slave parametrised again: in the log at once, then, until it is in data exchange,
        once every :data:`RESTARTS_SAID_EVERY` seconds with how often (a slave that refuses
        its parameters, a wrong ident say, is parametrised again every cycle)."""
        ctx = {"line": self.name, "drive": name}
        said = self._restarts.get(name)
        if said is None:
            self._restarts[name] = (now, 0)
            log.warning("drive %s: parametrised again (%s)", name, reason, extra=ctx)
            return
        at, since = said[0], said[1] + 1
        if now - at < RESTARTS_SAID_EVERY:
            self._restarts[name] = (at, since)
            return
        self._restarts[name] = (now, 0)
        log.warning(
            "drive %s: parametrised again %d times in %.0f s, not in data exchange since (%s"
            " the last time): %s", name, since, now - at, reason, self._refusal(name), extra=ctx,
        )  # fmt: skip

    def _refusal(self, name: str) -> str:
        """What the slave's latest diagnosis says it refuses (else: see its diagnosis)."""
        spec = next((s for s in self.drives if s.name == name), None)
        d = self._diagnoses.get(name)
        if spec is None or d is None:
            return "see its diagnosis"
        setup = spec.setup
        found = refusal(setup.address, d.flags, d.ident, setup.parameters.ident, CONFIGURATION)
        return found or "see its diagnosis"

    def _tell(self, planner: Planner, name: str, up: bool, reason: str, now: float) -> None:
        self._told.add(name)
        planner.told_health(name, up, reason, now)

    def _state(self, planner: Planner, name: str, event: StateChanged, now: float) -> None:
        self._events.append(SlaveStateChanged(name, event.new))
        ctx = {"line": self.name, "drive": name}
        if event.new is SlaveState.DATA_EXCHANGE:
            log.info("drive %s: in data exchange", name, extra=ctx)
            self._restarts.pop(name, None)
            self._tell(planner, name, True, "", now)
        elif event.old is SlaveState.DATA_EXCHANGE:
            self._tell(planner, name, False, f"left data exchange ({event.new})", now)
        elif event.new is SlaveState.LOCKED:
            log.error(
                "drive %s: owned by another master: pkwbus does not parametrise it", name,
                extra=ctx,
            )  # fmt: skip
