"""The master's view of one DP slave, as a state machine without I/O.

Feed it the time and what came back; it says which request to send next.
Start-up (EN 50170 vol. 2 part 3, "master-slave start-up"; Felser PROFIBUS
manual, "telegram sequence"): Slave_Diag, Set_Prm, Chk_Cfg, Slave_Diag until
ready, then cyclic Data_Exchange. An RS answer, a diagnosis asking for
parameters, a diagnosis fault or a watchdog that must have run out send the
slave back to a fresh start (FCB reset). A slave whose diagnosis names
another master is never parametrised: it stays ``locked`` and only its
diagnosis is read again now and then. A request that gets no valid answer is
repeated with the same FCB up to ``retries`` times; then the slave is offline
and is probed again every ``probe_interval`` seconds.

A DP-V1 slave (``SlaveSetup.dpv1``) is parametrised with DP-V1 on, and in data
exchange carries one record transfer at a time over MSAC_C1
(:class:`~pkwbus.protocol.profibus.dpv1.transfer.C1Transfer`): :meth:`DpSlave.poll_acyclic`
gives its next request, sent between two Data_Exchanges, and its end comes
back as a :class:`TransferEnded` event.
"""

from __future__ import annotations

import enum

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp.services import Diagnosis, Service, decode_diagnosis, request
from pkwbus.protocol.profibus.dp.slave_model import (
    Answer,
    DiagnosisRead,
    Failed,
    FailureKind,
    Garbled,
    Inputs,
    NoAnswer,
    Restarted,
    RestartReason,
    SlaveEvent,
    SlaveSetup,
    SlaveState,
    StateChanged,
    TransferEnded,
)
from pkwbus.protocol.profibus.dpv1.msac import C1_SAP, C1Answer, decode_c1, request_frame
from pkwbus.protocol.profibus.dpv1.transfer import (
    NO_DATA,
    C1Transfer,
    NoData,
    RecordFailed,
    TransferEnd,
)
from pkwbus.protocol.profibus.fdl import DataFrame, Status

__all__ = [
    "Answer",
    "DiagnosisRead",
    "DpSlave",
    "Failed",
    "FailureKind",
    "Garbled",
    "Inputs",
    "NoAnswer",
    "RestartReason",
    "Restarted",
    "SlaveEvent",
    "SlaveSetup",
    "SlaveState",
    "StateChanged",
    "TransferEnded",
]


class _Step(enum.Enum):
    DIAG = "first diagnosis"
    PRM = "Set_Prm"
    CFG = "Chk_Cfg"
    DIAG_READY = "diagnosis until ready"
    EXCHANGE = "Data_Exchange"
    DIAG_EXCHANGE = "diagnosis in data exchange"


_AFTER_PRM = frozenset({_Step.CFG, _Step.DIAG_READY, _Step.EXCHANGE, _Step.DIAG_EXCHANGE})
_FAULTS = frozenset({"cfg_fault", "prm_fault", "not_supported"})


class DpSlave:
    """One slave's start-up and data exchange: ``poll(now)`` to send, ``feed(answer, now)``."""

    def __init__(self, setup: SlaveSetup) -> None:
        self.setup = setup
        self.state = SlaveState.OFFLINE
        self.diagnosis: Diagnosis | None = None
        self._step = _Step.DIAG
        self._fcb = True
        self._fcv = False
        self._pending: DataFrame | None = None
        self._tries = 0
        self._due = float("-inf")
        self._last_answer: float | None = None
        self._events: list[SlaveEvent] = []
        self._probe_wait = setup.probe_interval  # doubles while offline or locked
        self.transfer: C1Transfer | None = None  # the record transfer in progress (DP-V1)
        self._acyclic = False  # the request out is the transfer's

    # ----------------------------------------------------------- sending

    @property
    def waiting(self) -> bool:
        """A request is out and its answer (or timeout) has not been fed."""
        return self._pending is not None

    def poll(self, now: float, outputs: bytes | None = None) -> DataFrame | None:
        """The request to send now (a repeat while one is unanswered), or None if none is due.

        ``outputs`` are the Data_Exchange outputs (the PPO-write); all zero when None.
        """
        transfer = self.transfer
        stalled = self._step is not _Step.EXCHANGE and not self._acyclic
        if transfer is not None and stalled and now >= transfer.deadline:
            # The transfer cannot go on (the slave keeps another step, its diagnosis, say)
            # and its time is up: it ends, whatever the slave does meanwhile.
            self._end_transfer(RecordFailed(
                f"no answer to the record transfer within the slave's response timeout"
                f" ({transfer.setup.response_timeout:g} s)", timed_out=True,
            ))  # fmt: skip
        if self._pending is not None:
            return self._pending
        if now < self._due:
            return None
        if self._step in _AFTER_PRM and self._watchdog_expired(now):
            self._restart(RestartReason.WATCHDOG, now)
        frame = self._build(outputs)
        self._pending = frame
        return frame

    def start_transfer(self, slot: int, index: int, data: bytes, now: float) -> None:
        """Write ``data`` to record ``index`` of ``slot`` and read its answer back, between
        the Data_Exchanges; LocalProtocolError when the slave cannot take it now."""
        dpv1 = self.setup.dpv1
        if dpv1 is None or not dpv1.read_write:
            raise LocalProtocolError(f"slave {self.setup.address} is no DP-V1 slave with records")
        if self.state is not SlaveState.DATA_EXCHANGE:
            raise LocalProtocolError(f"slave {self.setup.address} is not in data exchange")
        if self.transfer is not None:
            raise LocalProtocolError(f"slave {self.setup.address} has a transfer in progress")
        self.transfer = C1Transfer(slot, index, data, dpv1, now)

    def poll_acyclic(self) -> DataFrame | None:
        """The transfer's next request, to send after this cycle's Data_Exchange; None when
        there is none (or the slave is out of data exchange, or a request is out)."""
        transfer = self.transfer
        if transfer is None or self._pending is not None or self._step is not _Step.EXCHANGE:
            return None
        setup = self.setup
        pdu = transfer.next_pdu()
        frame = request_frame(setup.address, setup.master, pdu, fcb=self._fcb, fcv=self._fcv)
        self._pending = frame
        self._acyclic = True
        return frame

    def repeat_acyclic(self) -> DataFrame | None:
        """The transfer's request again, at once, while it is unanswered and retries are
        left (None otherwise). The FDL repeats a request as soon as its slot time is
        over, so the repeat holds up neither the next cycle's Data_Exchange nor the
        slaves after this one."""
        return self._pending if self._acyclic else None

    def take_events(self) -> list[SlaveEvent]:
        """Events produced by :meth:`poll` (a watchdog restart) since the last call."""
        events, self._events = self._events, []
        return events

    def _watchdog_expired(self, now: float) -> bool:
        seconds = self.setup.parameters.watchdog_seconds
        return (
            seconds is not None
            and self._last_answer is not None
            and now - self._last_answer >= seconds
        )

    def _build(self, outputs: bytes | None) -> DataFrame:
        setup = self.setup
        data = b""
        service: Service | None
        if self._step in (_Step.DIAG, _Step.DIAG_READY, _Step.DIAG_EXCHANGE):
            service = Service.SLAVE_DIAG
        elif self._step is _Step.PRM:
            service, data = Service.SET_PRM, setup.prm_data()
        elif self._step is _Step.CFG:
            service, data = Service.CHK_CFG, setup.cfg
        else:
            service = None
            data = bytes(setup.outputs) if outputs is None else outputs
            if len(data) != setup.outputs:
                raise LocalProtocolError(
                    f"{len(data)} output bytes for a configuration of {setup.outputs}"
                )
        return request(service, setup.address, setup.master, data, fcb=self._fcb, fcv=self._fcv)

    # --------------------------------------------------------- receiving

    def feed(self, answer: Answer, now: float) -> list[SlaveEvent]:
        """Account for the answer to the pending request (or its absence); the events since
        the last call (a watchdog restart found by :meth:`poll` included)."""
        if self._pending is None:
            raise LocalProtocolError("an answer fed with no request out")
        if self._acyclic and not isinstance(answer, NoAnswer | Garbled):
            self._on_c1(answer, now)
        elif isinstance(answer, NoAnswer):
            self._fail(FailureKind.TIMEOUT, "no answer", now)
        elif isinstance(answer, Garbled):
            self._fail(FailureKind.GARBLED, answer.detail, now)
        else:
            self._on_frame(answer, now)
        events, self._events = self._events, []
        return events

    def _on_frame(self, frame: fdl.Frame, now: float) -> None:
        setup = self.setup
        status: Status | None
        if isinstance(frame, fdl.ShortAck):
            status, data = Status.OK, b""
        elif (
            isinstance(frame, DataFrame)
            and frame.sa == setup.address
            and frame.da == setup.master
            and not frame.control.is_request
        ):
            status, data = frame.control.status, frame.data
        else:
            self._fail(FailureKind.UNEXPECTED, f"{frame} is not this slave's answer", now)
            return
        if status is Status.RS:
            self._answered(now)
            self._restart(RestartReason.RS, now)
            return
        if status is None or status in (Status.UE, Status.RR, Status.RDL, Status.RDH):
            self._fail(FailureKind.REFUSED, f"answer FC {frame}", now)
            return
        step = self._step
        if step in (_Step.PRM, _Step.CFG):
            if data or status is not Status.OK:
                self._fail(FailureKind.UNEXPECTED, "data in answer to Set_Prm/Chk_Cfg", now)
                return
            self._answered(now)
            if step is _Step.PRM:
                self._go(_Step.CFG, SlaveState.WAIT_CFG)
            else:
                self._go(_Step.DIAG_READY, SlaveState.WAIT_CFG)
            return
        if step is _Step.EXCHANGE:
            self._on_exchange(status, data, now)
            return
        try:
            diagnosis = decode_diagnosis(data)
        except RemoteProtocolError as exc:
            self._fail(FailureKind.UNEXPECTED, str(exc), now)
            return
        self._answered(now)
        self.diagnosis = diagnosis
        self._events.append(DiagnosisRead(diagnosis))
        self._on_diagnosis(diagnosis, now)

    def _on_c1(self, frame: fdl.Frame, now: float) -> None:
        """The answer to a transfer's request: its next step, or its end."""
        transfer = self.transfer
        assert transfer is not None  # the request out is its
        setup = self.setup
        if isinstance(frame, fdl.ShortAck):
            said: C1Answer | NoData | RecordFailed = NO_DATA
        elif (
            isinstance(frame, DataFrame)
            and frame.sa == setup.address
            and frame.da == setup.master
            and not frame.control.is_request
        ):
            status = frame.control.status
            if status is Status.RS:
                said = RecordFailed(
                    "the slave has no MSAC_C1 service access point (51) active:"
                    " it does not run DP-V1"
                )
            elif status in (Status.NR, Status.OK) and not frame.data:
                said = NO_DATA
            elif frame.dsap != C1_SAP or status not in (Status.DL, Status.DH, Status.OK):
                said = RecordFailed(f"{frame} answers an MSAC_C1 request")
            else:
                try:
                    said = decode_c1(frame.data, transfer.function, transfer.slot, transfer.index)
                except RemoteProtocolError as exc:
                    said = RecordFailed(str(exc))
        else:
            self._fail(FailureKind.UNEXPECTED, f"{frame} is not this slave's answer", now)
            return
        self._answered(now)
        end = said if isinstance(said, RecordFailed) else transfer.feed(said, now)
        if end is not None:
            self._end_transfer(end)

    def _end_transfer(self, end: TransferEnd) -> None:
        self.transfer = None
        self._events.append(TransferEnded(end))

    def _on_exchange(self, status: Status, data: bytes, now: float) -> None:
        expected = self.setup.inputs
        if len(data) != expected:
            what = f"{len(data)} input bytes, configured {expected}"
            self._fail(FailureKind.UNEXPECTED, what, now)
            return
        self._answered(now)
        pending = status in (Status.DH, Status.RDH)
        self._events.append(Inputs(data, pending))
        if pending:
            self._step = _Step.DIAG_EXCHANGE

    def _on_diagnosis(self, diag: Diagnosis, now: float) -> None:
        step = self._step
        if diag.owned_by_other(self.setup.master):
            self._lock(now)
            return
        if step is _Step.DIAG:
            self._go(_Step.PRM, SlaveState.WAIT_PRM)
        elif "prm_required" in diag.flags:
            self._restart(RestartReason.PRM_REQUIRED, now)
        elif diag.flags & _FAULTS:
            self._restart(RestartReason.DIAG, now, wait=True)
        elif step is _Step.DIAG_READY:
            if diag.ready:
                self._go(_Step.EXCHANGE, SlaveState.DATA_EXCHANGE)
        elif "not_ready" in diag.flags:
            self._restart(RestartReason.DIAG, now, wait=True)
        elif "stat_diag" not in diag.flags:
            self._step = _Step.EXCHANGE  # diagnosis fetched, back to data exchange

    # ----------------------------------------------------------- helpers

    def _answered(self, now: float) -> None:
        """A request completed: FCB toggles, FCV on from now."""
        self._pending = None
        self._acyclic = False
        self._tries = 0
        self._fcb = not self._fcb
        self._fcv = True
        self._last_answer = now

    def _fail(self, kind: FailureKind, detail: str, now: float) -> None:
        self._events.append(Failed(kind, detail))
        self._tries += 1
        if self._tries <= self.setup.retries:
            return  # the pending request goes again, same FCB
        if kind is FailureKind.TIMEOUT or self.state is SlaveState.OFFLINE:
            self._fresh(now + self._next_probe())
            self._set_state(SlaveState.OFFLINE)
        else:
            self._restart(RestartReason.DIAG, now, wait=True)

    def _restart(self, reason: RestartReason, now: float, *, wait: bool = False) -> None:
        self._events.append(Restarted(reason))
        self._fresh(now + self.setup.probe_interval if wait else now)
        self._set_state(SlaveState.WAIT_PRM)

    def _lock(self, now: float) -> None:
        self._fresh(now + self._next_probe())
        self._set_state(SlaveState.LOCKED)

    def _next_probe(self) -> float:
        """The wait before the next probe of a slave that is offline or locked: capped
        exponential back-off, so that a dead slave costs the line less and less."""
        wait = self._probe_wait
        self._probe_wait = min(self.setup.probe_cap, max(wait * 2, self.setup.probe_interval))
        return wait

    def _fresh(self, due: float) -> None:
        if self.transfer is not None:
            self._end_transfer(RecordFailed("the slave left data exchange"))
        self._acyclic = False
        self._step = _Step.DIAG
        self._pending = None
        self._tries = 0
        self._fcb, self._fcv = True, False
        self._due = due
        self._last_answer = None

    def _go(self, step: _Step, state: SlaveState) -> None:
        self._step = step
        self._set_state(state)

    def _set_state(self, state: SlaveState) -> None:
        if state is SlaveState.DATA_EXCHANGE:
            self._probe_wait = self.setup.probe_interval  # in service again: back-off over
        if state is not self.state:
            self._events.append(StateChanged(self.state, state))
            self.state = state
