"""The DP master of one line: its slaves in turn, one Data_Exchange each per cycle.

Each slave has its start-up state machine (:class:`~pkwbus.protocol.profibus.dp.slave.DpSlave`)
and, when its PPO has a parameter channel, a PKW slot
(:class:`~pkwbus.protocol.profibus.dp.ppo.PkwSlot`) whose request goes in every PPO-write
until its job is over; every answer while it does goes to ``on_event`` as a
:class:`~pkwbus.protocol.profibus.dp.ppo.SlotAnswer`, for the job to judge. Who fills the
slots and ends their jobs is the caller's: the line runner's cycle wire, per
slave and per cycle, with what its planner gives (``Planner.next_for``)
through the ``feed`` hook. A DP-V1 slave's record transfer (PROFIdrive data
record 47), started by the same hook, sends one MSAC_C1 request after the
slave's Data_Exchange in each cycle, so every slave keeps its cycle; its end
comes to ``on_event`` as a :class:`~pkwbus.protocol.profibus.dp.slave.TransferEnded`.
Stopping sends Global_Control Clear to every slave, then closes the port.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from pkwbus.link import PortError
from pkwbus.master.wires.profibus.line import DpLine, ForeignMaster
from pkwbus.protocol.profibus.dp.ppo import PkwSlot, SlotAnswer, SlotGarbled
from pkwbus.protocol.profibus.dp.services import global_control_clear
from pkwbus.protocol.profibus.dp.slave import (
    DpSlave,
    Failed,
    Inputs,
    SlaveEvent,
    SlaveSetup,
    SlaveState,
)
from pkwbus.protocol.profibus.fdl import DataFrame

__all__ = ["DpMaster", "ForeignMaster", "SlaveLocked", "SlaveRun"]

IDLE_STEP = 0.01  # seconds a cycle with nothing due waits before the next


class SlaveLocked(Exception):
    """The slave's diagnosis names another master: it is never parametrised."""

    def __init__(self, address: int, owner: int | None) -> None:
        self.address = address
        self.owner = owner
        super().__init__(
            f"slave {address} is owned by master {owner}: pkwbus does not parametrise it"
            " and sent it nothing but diagnosis requests"
        )


@dataclass
class SlaveRun:
    """One slave on the line: its state machine and its PKW slot (None: PPO 3/4)."""

    slave: DpSlave
    slot: PkwSlot | None

    @property
    def address(self) -> int:
        return self.slave.setup.address


EventHook = Callable[[int, "SlaveEvent | SlotAnswer | SlotGarbled"], None]
# A request other than Data_Exchange answered (diagnosis, Set_Prm, Chk_Cfg): the slave's
# address, how long the answer took and how long the request held the line.
AnsweredHook = Callable[[int, float, float], None]
# Each cycle, before its slave's turn: fill an idle slot, end a job past its deadline.
Feed = Callable[[SlaveRun, float], None]


class DpMaster:
    """The slaves of one DP line, cycled in turn over its :class:`DpLine`."""

    def __init__(
        self,
        line: DpLine,
        slaves: Sequence[tuple[SlaveSetup, PkwSlot | None]],
        *,
        on_event: EventHook | None = None,
        feed: Feed | None = None,
        on_answered: AnsweredHook | None = None,
    ) -> None:
        self.line = line
        self.runs = {s.address: SlaveRun(DpSlave(s), slot) for s, slot in slaves}
        self.on_event = on_event
        self.feed = feed
        self.on_answered = on_answered
        self.cycles = 0
        # How long the latest request held the line: from its start (the idle time before
        # it included) to its answer or the end of the slot time, in loop seconds; and
        # how long its answer took from the request written, as on FC and USS lines.
        self.exchange_time = 0.0
        self.answer_time = 0.0

    async def start(self, *, listen: float | None = None) -> None:
        """Open the port and listen for other masters; :class:`ForeignMaster`, PortError."""
        await self.line.open()
        try:
            await self.line.listen(listen)
        except ForeignMaster:
            await self.line.close()
            raise

    async def stop(self) -> None:
        """Global_Control Clear to every slave (when the port is still there), then close."""
        with contextlib.suppress(PortError, ForeignMaster):
            if self.line.is_open and self.line.foreign is None and self.line.requests:
                await self.line.broadcast(global_control_clear(self.line.master))
        await self.line.close()

    async def cycle(self) -> int:
        """One Data_Exchange (or start-up request) per slave, in turn; the requests sent."""
        loop = asyncio.get_running_loop()
        sent = 0
        for run in self.runs.values():
            now = loop.time()
            slot = run.slot
            if self.feed is not None:
                self.feed(run, now)
            slave = run.slave
            exchanging = slave.state is SlaveState.DATA_EXCHANGE and not slave.waiting
            outputs = slot.outputs() if exchanging and slot is not None else None
            frame = slave.poll(now, outputs)
            for event in slave.take_events():
                self._emit(run, event)
            if frame is None:
                continue
            await self._exchange(run, frame)
            sent += 1
            acyclic = slave.poll_acyclic()  # a record transfer's next request, if any
            while acyclic is not None:  # and its repeats, while unanswered
                await self._exchange(run, acyclic)
                sent += 1
                acyclic = slave.repeat_acyclic()
        self.cycles += 1
        if not sent:
            await asyncio.sleep(IDLE_STEP)
        return sent

    async def _exchange(self, run: SlaveRun, frame: DataFrame) -> None:
        """One request to the slave and its answer fed back; its events told."""
        loop = asyncio.get_running_loop()
        started = loop.time()
        answer = await self.line.exchange(frame)
        now = loop.time()
        self.exchange_time = now - started
        self.answer_time = now - self.line.sent_at
        slot = run.slot
        told = False  # an Inputs or a Failed event tells the exchange to on_event
        for event in run.slave.feed(answer, now):
            update = None
            if isinstance(event, Inputs) and slot is not None:
                update = slot.feed(event.data)
                if update.garbled is not None:  # told before the exchange it came with
                    self._emit(run, update.garbled)
            self._emit(run, event)
            told = told or isinstance(event, Inputs | Failed)
            if update is not None and update.answer is not None:
                self._emit(run, update.answer)
        if not told and self.on_answered is not None:
            self.on_answered(run.address, self.answer_time, self.exchange_time)

    def _emit(self, run: SlaveRun, event: SlaveEvent | SlotAnswer | SlotGarbled) -> None:
        if self.on_event is not None:
            self.on_event(run.address, event)
