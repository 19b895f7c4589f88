"""The DP cycle over a real :class:`FdlPort`, one cycle at a time, and one job through a
slave's start-up and PKW slot: the test harness of the cycle and the line (the command
line and the service drive both through the line runner, :mod:`pkwbus.master.runner`)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Sequence

from pkwbus.link import PortError
from pkwbus.master.carriers import SlotCarrier
from pkwbus.master.planning.answers import Reply
from pkwbus.master.planning.carrier import Item
from pkwbus.master.planning.outcomes import LineFailed, Outcome, TimedOut
from pkwbus.master.wires.profibus.cycle import IDLE_STEP, CycleEvent, SlaveCycle, SlaveLocked
from pkwbus.master.wires.profibus.port import FdlPort, ForeignMaster
from pkwbus.protocol import pkw
from pkwbus.protocol.profibus.dp.ppo import PkwSlot, SlotAnswer
from pkwbus.protocol.profibus.dp.services import global_control_clear
from pkwbus.protocol.profibus.dp.slave import (
    Failed,
    FailureKind,
    SlaveSetup,
    SlaveState,
    StateChanged,
)
from pkwbus.protocol.profibus.fdl import DataFrame

EventHook = Callable[[int, CycleEvent], None]


class CycleHarness:
    """The pure :class:`SlaveCycle` of a few slaves, its requests sent on a :class:`FdlPort`
    and its answers fed back, one whole cycle per :meth:`cycle`; every event to ``on_event``."""

    def __init__(
        self,
        line: FdlPort,
        slaves: Sequence[tuple[SlaveSetup, PkwSlot | None]],
        *,
        on_event: EventHook | None = None,
    ) -> None:
        self.line = line
        self.slave_cycle = SlaveCycle(slaves)
        self.runs = self.slave_cycle.runs
        self.on_event = on_event
        self._held: DataFrame | None = None  # the next cycle's first request

    async def start(self, *, listen: float | None = None) -> None:
        """Open the port and listen for other masters; :class:`ForeignMaster`, PortError."""
        self.line.listen_for = listen
        await self.line.open()
        try:
            await self.line.started()
        except ForeignMaster:
            await self.line.close()
            raise

    async def stop(self) -> None:
        """Global_Control Clear to every slave (when the port is still there), then close."""
        with contextlib.suppress(PortError, ForeignMaster):
            if self.line.is_open and self.line.foreign is None and self.line.requests:
                await self.line.broadcast(global_control_clear(self.line.master))
        await self.line.close()

    @property
    def cycles(self) -> int:
        return self.slave_cycle.cycles

    async def cycle(self) -> int:
        """One Data_Exchange (or start-up request) per slave, in turn; the requests sent."""
        loop = asyncio.get_running_loop()
        cycle = self.slave_cycle
        begun = cycle.cycles
        sent = 0
        while True:
            frame, self._held = self._held, None
            if frame is None:
                frame = cycle.transmit(loop.time(), lambda run, now: None)
                self._tell()
            if frame is None:
                await asyncio.sleep(IDLE_STEP)
                return sent
            if cycle.cycles != begun:  # the first request of the next cycle
                self._held = frame
                return sent
            answer = await self.line.exchange(frame)
            cycle.received(answer, loop.time())
            sent += 1
            self._tell()

    def _tell(self) -> None:
        for run, event in self.slave_cycle.take_events():
            if self.on_event is not None:
                self.on_event(run.address, event)


async def run_dp_job(
    master: CycleHarness, address: int, request: pkw.PkwRequest, *, deadline: float
) -> Outcome:
    """One job through a slave's start-up and its PKW slot, on a started master.

    :class:`SlaveLocked` when the slave belongs to another master,
    :class:`ForeignMaster` when another master is heard on the line.
    """
    run = master.runs[address]
    slot = run.slot
    if slot is None:
        raise ValueError(f"slave {address} has no parameter channel")
    loop = asyncio.get_running_loop()
    # The job judged by the one rule of every bus: the master's PKW transaction.
    carrier = SlotCarrier(address, slot.ppo, slot.dialect)
    carrier.slot = slot  # the slot the harness cycles: the carrier takes what it read
    tx = carrier.transaction([Item(request)], retries=0, deadline=deadline)
    slot.submit(request)
    result: list[Outcome] = []
    gone: list[str] = []
    hook = master.on_event

    def watch(addr: int, event: CycleEvent) -> None:
        if hook is not None:
            hook(addr, event)
        if addr != address:
            return
        if isinstance(event, SlotAnswer):
            assert slot.update is not None
            answer = Reply(address, slot.update.inputs, 0.0)  # as the DP wire hands it over
            if (outcome := tx.feed(answer, loop.time())) is not None:
                result.append(outcome)
        elif isinstance(event, StateChanged) and event.new is SlaveState.LOCKED:
            gone.append("locked")
        elif (
            isinstance(event, Failed)
            and event.kind is FailureKind.TIMEOUT
            and run.slave.state is SlaveState.OFFLINE
            and not run.slave.waiting
        ):
            gone.append(f"slave {address} does not answer ({event.detail})")

    master.on_event = watch
    try:
        while not result:
            if gone:
                if gone[0] == "locked":
                    diagnosis = run.slave.diagnosis
                    raise SlaveLocked(address, diagnosis.master if diagnosis else None)
                return TimedOut(gone[0])
            if loop.time() >= deadline:
                return TimedOut(f"no matching answer within the deadline ({slot.cycles} cycles)")
            try:
                await master.cycle()
            except PortError as exc:
                return LineFailed(str(exc))
        return result[0]
    finally:
        slot.finish()
        master.on_event = hook
