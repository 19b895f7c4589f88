"""A simulated PROFIBUS DP-V0 slave: the slave's state machine around a simulated drive.

Pure: frames and the time in, the answer frame out. WAIT_PRM (only a valid
Set_Prm moves on) -> WAIT_CFG (a Chk_Cfg equal to its configuration) ->
DATA_EXCH; with the watchdog on, a master silent for the watchdog time sends
it back to WAIT_PRM. A repeated request (FCV set, same FCB) gets the previous
answer again. Data_Exchange outputs go to the drive as a PKW + PZD block, and
the drive's answer block is the PPO-read.
"""

from __future__ import annotations

import enum
from collections.abc import Callable

from pkwbus.protocol import fdl
from pkwbus.protocol.dp_services import (
    Diagnosis,
    Service,
    decode_parameters,
    encode_diagnosis,
    io_lengths,
)
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.fdl import BROADCAST, DataFrame, ShortAck, Status

__all__ = ["Respond", "SimDpSlave", "SlaveMode"]

Respond = Callable[[bytes, float], bytes]  # outputs (PPO-write), now -> inputs (PPO-read)


class SlaveMode(enum.StrEnum):
    WAIT_PRM = "wait_prm"
    WAIT_CFG = "wait_cfg"
    DATA_EXCH = "data_exchange"


class SimDpSlave:
    """One slave on a simulated DP line."""

    def __init__(self, address: int, ident: int, cfg: bytes, respond: Respond) -> None:
        self.address = address
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
