"""Every value a simulated line sent in a valid answer, to check what the service exports.

A value counts when it left the simulator in a frame with a good checksum, from
the drive the request was for, after its fault was applied: a dropped,
corrupted or cut answer is not there, a stale one is there again. Values are
kept as engineering values, decoded with the simulated drive's own type and
scaling, rounded to 9 significant digits (the service may scale in another
order of operations; one step of any raw number is far larger).
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from pkwbus.protocol import pkw
from pkwbus.protocol.buses import decode_adr
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.serial.telegram import Telegram, split_block
from pkwbus.protocol.values import decode_value
from pkwbus.sim import Simulator
from pkwbus.sim.drives.drive import SimDrive
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.profibus.line import DpSimulator

__all__ = ["Key", "SentValues", "rounded"]

Key = tuple[int, int, int]  # address, PNU, index


def rounded(value: float) -> float:
    return float(f"{value:.9g}")


class SentValues:
    """The values one line sent, by drive address, PNU and index."""

    def __init__(self, sim: Simulator | DpSimulator) -> None:
        self.sim = sim
        self.values: defaultdict[Key, set[float]] = defaultdict(set)
        answer = sim.answer
        if isinstance(sim, DpSimulator):

            def logged_dp(frame: Any, now: float | None = None) -> Answer | None:
                out = answer(frame, now)
                if out is not None and isinstance(frame, fdl.DataFrame):
                    self._dp_answer(sim, frame.da, out.data)
                return out

            sim.answer = logged_dp  # type: ignore[method-assign]
        else:

            def logged(telegram: Telegram, now: float | None = None) -> Answer | None:
                out = answer(telegram, now)
                if out is not None:
                    self._answer(sim, decode_adr(sim.protocol, telegram.adr).address, out.data)
                return out

            sim.answer = logged  # type: ignore[method-assign]

    def sent(self, key: Key, value: float) -> bool | None:
        """Whether the line sent ``value`` for ``key``; None when it sent nothing for it."""
        seen = self.values.get(key)
        return None if not seen else rounded(value) in seen

    def _answer(self, sim: Simulator, address: int, data: bytes) -> None:
        for event in sim.deframer().feed(data):
            if not isinstance(event, Telegram):
                continue
            if decode_adr(sim.protocol, event.adr).address != address:
                continue
            try:
                block = split_block(event.data, sim.shape)
                if len(block.pkw) < 4:
                    continue
                resp = pkw.decode_response(block.pkw, sim.dialect, sim.layout)
            except RemoteProtocolError:
                continue
            self._value(sim.drives[address], resp)

    def _dp_answer(self, sim: DpSimulator, address: int, data: bytes) -> None:
        drive = sim.drives.get(address)
        if drive is None:
            return
        for event in fdl.Deframer().feed(data):
            if not isinstance(event, fdl.DataFrame) or event.sa != address:
                continue
            if event.dsap is not None or len(event.data) != sim.ppo.length:
                continue  # not a Data_Exchange answer
            try:
                read = ppo.decode_ppo_read(sim.ppo, drive.dialect, event.data)
            except RemoteProtocolError:
                continue
            if read.pkw is not None:
                self._value(drive, read.pkw)

    def _value(self, drive: SimDrive, resp: pkw.PkwResponse) -> None:
        if not isinstance(resp, pkw.ValueResponse):
            return
        spec = drive.params.specs.get(resp.pnu)
        if spec is None:
            return
        try:
            number = decode_value(resp.raw, resp.width, spec.vtype, spec.scaling)
        except (RemoteProtocolError, ValueError):
            return
        self.values[drive.address, resp.pnu, resp.subindex].add(rounded(float(number)))
