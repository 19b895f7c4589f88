"""A simulated PROFIBUS DP-V0 slave: the slave's state machine around a simulated drive.

Pure: frames and the time in, the answer frame out. WAIT_PRM (only a valid
Set_Prm moves on) -> WAIT_CFG (a Chk_Cfg equal to its configuration) ->
DATA_EXCH; with the watchdog on, a master silent for the watchdog time sends
it back to WAIT_PRM. A repeated request (FCV set, same FCB) gets the previous
answer again. Data_Exchange outputs go to the drive as a PKW + PZD block, and
the drive's answer block is the PPO-read.

A slave with ``records`` is a DP-V1 slave: parametrised with DP-V1 on, in data
exchange it takes MSAC_C1 writes of data record 47 (slot ``record_slot``) and
answers the read that follows with the drive's response, after answering
``not_ready`` reads with "state conflict" (``DE 80 B5 00``); a read with no
request written is a state conflict too, another record an invalid index.
"""

from __future__ import annotations

import enum
from collections.abc import Callable

from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp.services import (
    Diagnosis,
    Service,
    decode_parameters,
    encode_diagnosis,
    io_lengths,
)
from pkwbus.protocol.profibus.dpv1.msac import (
    C1_SAP,
    NOT_READY,
    C1Function,
    Dpv1Status,
    decode_c1_request,
    encode_c1_error,
)
from pkwbus.protocol.profibus.fdl import BROADCAST, DataFrame, ShortAck, Status
from pkwbus.protocol.profidrive.parameters import RECORD

__all__ = ["Respond", "SimDpSlave", "SlaveMode"]

Respond = Callable[[bytes, float], bytes]  # outputs (PPO-write), now -> inputs (PPO-read)
Records = Callable[[bytes], bytes]  # a data record 47 request -> its response
_INVALID_INDEX = 0xB0
_INVALID_SLOT = 0xB2
_WRITE_ERROR = 0xA1


class SlaveMode(enum.StrEnum):
    WAIT_PRM = "wait_prm"
    WAIT_CFG = "wait_cfg"
    DATA_EXCH = "data_exchange"


class SimDpSlave:
    """One slave on a simulated DP line."""

    def __init__(
        self,
        address: int,
        ident: int,
        cfg: bytes,
        respond: Respond,
        *,
        records: Records | None = None,
        record_slot: int = 0,
        not_ready: int = 0,
    ) -> None:
        self.address = address
        self.records = records
        self.record_slot = record_slot
        self.not_ready = not_ready  # reads answered "state conflict" before each response
        self.dpv1 = False  # parametrised with DP-V1 on
        self.record_writes = 0
        self._response: bytes | None = None  # the record's response, waiting to be read
        self._waits = 0
        self.ident = ident
        self.cfg = cfg
        self.respond = respond
        self.inputs, self.outputs = io_lengths(cfg)
        self.mode = SlaveMode.WAIT_PRM
        self.owner: int | None = None
        self.watchdog: float | None = None
        self.prm_fault = False
        self.cfg_fault = False
        self.clears = 0  # Global_Control Clear frames seen
        self.timeouts = 0  # watchdog expiries
        self._last_request: float | None = None
        self._last_fcb: bool | None = None
        self._last_answer: fdl.Frame | None = None

    def tick(self, now: float) -> None:
        """The watchdog: a master silent for its time sends the slave back to WAIT_PRM."""
        if (
            self.mode is not SlaveMode.WAIT_PRM
            and self.watchdog is not None
            and self._last_request is not None
            and now - self._last_request >= self.watchdog
        ):
            self.timeouts += 1
            self._reset()

    def lock_to(self, master: int) -> None:
        """Another master has parametrised the slave with lock and exchanges data with it.

        Its watchdog is off: that master's traffic, which would keep it running, is
        not simulated.
        """
        self.mode = SlaveMode.DATA_EXCH
        self.owner = master
        self.watchdog = None

    def release(self) -> None:
        """The owning master lets go: the slave waits for parameters from any master."""
        self._reset()

    def _reset(self) -> None:
        self.mode = SlaveMode.WAIT_PRM
        self.owner = None
        self.watchdog = None
        self.dpv1 = False
        self._response = None

    def handle(self, frame: fdl.Frame, now: float) -> fdl.Frame | None:
        """The answer to ``frame``; None when the slave stays silent (not for it, broadcast)."""
        if not isinstance(frame, DataFrame) or not frame.control.is_request:
            return None
        if frame.da == BROADCAST:
            if frame.dsap == Service.GLOBAL_CONTROL and frame.data[:1] == b"\x02":
                self.clears += 1
            return None
        if frame.da != self.address:
            return None
        control = frame.control
        if control.function is fdl.Function.FDL_STATUS:  # the live list: "a slave is here"
            return DataFrame(frame.sa, self.address, fdl.response_fc(Status.OK))
        self.tick(now)
        self._last_request = now
        if control.fcv and control.fcb == self._last_fcb and self._last_answer is not None:
            return self._last_answer  # a retry: the previous answer again
        answer = self._answer(frame, now)
        if control.fcv or control.fcb:
            self._last_fcb = control.fcb
            self._last_answer = answer
        return answer

    def _reply(self, frame: DataFrame, status: Status, data: bytes = b"") -> DataFrame:
        fc = fdl.response_fc(status)
        return DataFrame(frame.sa, self.address, fc, frame.ssap, frame.dsap, data)

    def _answer(self, frame: DataFrame, now: float) -> fdl.Frame:
        service = frame.dsap
        if service == Service.SLAVE_DIAG:
            return self._reply(frame, Status.DL, encode_diagnosis(self.diagnosis()))
        if service == Service.GET_CFG:
            return self._reply(frame, Status.DL, self.cfg)
        if service == Service.SET_PRM:
            self._set_prm(frame)
            return ShortAck()
        if service == Service.CHK_CFG:
            if self.mode is SlaveMode.WAIT_CFG and frame.sa == self.owner:
                self.cfg_fault = frame.data != self.cfg
                self.mode = SlaveMode.WAIT_PRM if self.cfg_fault else SlaveMode.DATA_EXCH
            return ShortAck()
        if service == C1_SAP and self.dpv1 and self.mode is SlaveMode.DATA_EXCH:
            if frame.sa != self.owner:
                return self._reply(frame, Status.RS)
            return self._reply(frame, Status.DL, self._c1(frame.data))
        if service is not None:
            return self._reply(frame, Status.RS)
        if self.mode is not SlaveMode.DATA_EXCH or frame.sa != self.owner:
            return self._reply(frame, Status.RS)
        if len(frame.data) != self.outputs:
            return self._reply(frame, Status.UE)
        inputs = self.respond(frame.data, now)
        return self._reply(frame, Status.DL, inputs)

    def _set_prm(self, frame: DataFrame) -> None:
        if self.owner is not None and self.owner != frame.sa:
            return  # locked by another master: not parametrised
        try:
            prm = decode_parameters(frame.data)
        except RemoteProtocolError:
            self.prm_fault = True
            return
        self.prm_fault = prm.ident != self.ident
        if self.prm_fault:
            self._reset()
            return
        self.mode = SlaveMode.WAIT_CFG
        self.cfg_fault = False
        self.owner = frame.sa if prm.lock else None
        self.watchdog = prm.watchdog_seconds
        self.dpv1 = self.records is not None and Dpv1Status.decode(prm.user_prm) is not None
        self._response = None

    def _c1(self, data: bytes) -> bytes:
        """An MSAC_C1 request's answer: a record 47 request written, its response read."""
        try:
            request = decode_c1_request(data)
        except RemoteProtocolError:
            function = (
                C1Function.WRITE if data[:1] == bytes((C1Function.WRITE,)) else C1Function.READ
            )
            return encode_c1_error(function, _WRITE_ERROR)
        function = request.function
        if request.slot != self.record_slot:
            return encode_c1_error(function, _INVALID_SLOT)
        if request.index != RECORD:
            return encode_c1_error(function, _INVALID_INDEX)
        head = bytes((function, request.slot, request.index))
        if function is C1Function.WRITE:
            assert self.records is not None  # a DP-V1 slave has them
            try:
                self._response = self.records(request.data)
            except RemoteProtocolError:
                self._response = None
                return encode_c1_error(function, _WRITE_ERROR)
            self.record_writes += 1
            self._waits = self.not_ready
            return head + bytes((len(request.data),))
        if self._response is None or self._waits > 0:
            self._waits -= 1
            return encode_c1_error(function, NOT_READY)
        response, self._response = self._response, None
        return head + bytes((len(response),)) + response

    def diagnosis(self) -> Diagnosis:
        flags = set()
        if self.mode is SlaveMode.WAIT_PRM:
            flags.add("prm_required")
        if self.mode is not SlaveMode.DATA_EXCH:
            flags.add("not_ready")
        if self.prm_fault:
            flags.add("prm_fault")
        if self.cfg_fault:
            flags.add("cfg_fault")
        if self.watchdog is not None:
            flags.add("watchdog_on")
        return Diagnosis(frozenset(flags), self.owner, self.ident)
