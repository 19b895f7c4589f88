"""The slaves of one DP line in turn, one Data_Exchange (or start-up request) each a cycle:
what to send next and what an answer told, without I/O.

Each slave has its start-up state machine
(:class:`~pkwbus.protocol.profibus.dp.slave.DpSlave`) and, when its PPO has a
parameter channel, a PKW slot (:class:`~pkwbus.protocol.profibus.dp.ppo.PkwSlot`)
whose request goes in every PPO-write until its job is over; the slot decodes
each PPO-read once, and its answer (:class:`~pkwbus.protocol.profibus.dp.ppo.SlotAnswer`)
or why it could not be read (:class:`~pkwbus.protocol.profibus.dp.ppo.SlotGarbled`)
is among the events of the exchange. Who fills the slots is the caller's,
before each slave's turn (``before``). A DP-V1 slave's record transfer
(PROFIdrive data record 47) puts one MSAC_C1 request after the slave's
Data_Exchange, repeated at once while unanswered, so every slave keeps its
cycle; its end is a :class:`~pkwbus.protocol.profibus.dp.slave.TransferEnded`
event.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from pkwbus.errors import PkwbusError
from pkwbus.protocol.profibus.dp.ppo import PkwSlot, SlotAnswer, SlotGarbled
from pkwbus.protocol.profibus.dp.slave import (
    Answer,
    DpSlave,
    Failed,
    Inputs,
    SlaveEvent,
    SlaveSetup,
    SlaveState,
)
from pkwbus.protocol.profibus.fdl import DataFrame

__all__ = ["IDLE_STEP", "CycleEvent", "SlaveCycle", "SlaveLocked", "SlaveRun", "StartupAnswered"]

IDLE_STEP = 0.01  # seconds a cycle with nothing to send waits before the next


class SlaveLocked(PkwbusError):
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


@dataclass(frozen=True, slots=True)
class StartupAnswered:
    """A request other than Data_Exchange (diagnosis, Set_Prm, Chk_Cfg) was answered."""


CycleEvent = SlaveEvent | SlotAnswer | SlotGarbled | StartupAnswered
Before = Callable[[SlaveRun, float], None]


class SlaveCycle:
    """The slaves of one line, cycled in turn: pure calls, the caller does the I/O."""

    def __init__(self, slaves: Sequence[tuple[SlaveSetup, PkwSlot | None]]) -> None:
        self.runs = {s.address: SlaveRun(DpSlave(s), slot) for s, slot in slaves}
        self.cycles = 0
        self.events: list[tuple[SlaveRun, CycleEvent]] = []  # in order, until taken
        self._order = list(self.runs)
        self._next = 0  # the next slave's place in the cycle
        self._sent = 0  # requests of this cycle so far
        self._out: SlaveRun | None = None  # the slave whose request is out
        self._acyclic_out = False
        self._pending: DataFrame | None = None  # an acyclic request that follows at once
        self._left_out: set[int] = set()  # slaves sent nothing (a drive in maintenance)

    def transmit(self, now: float, before: Before) -> DataFrame | None:
        """The next request of the cycle (None: a cycle went by with nothing to send)."""
        pending = self._pending
        if pending is not None:
            self._pending = None
            self._acyclic_out = True
            return pending
        while True:
            while self._next < len(self._order):
                address = self._order[self._next]
                self._next += 1
                if address in self._left_out:
                    continue
                run = self.runs[address]
                before(run, now)
                slave, slot = run.slave, run.slot
                exchanging = slave.state is SlaveState.DATA_EXCHANGE and not slave.waiting
                outputs = slot.outputs() if exchanging and slot is not None else None
                frame = slave.poll(now, outputs)
                self.events += [(run, e) for e in slave.take_events()]
                if frame is not None:
                    self._out, self._acyclic_out = run, False
                    self._sent += 1
                    return frame
            self._next = 0
            self.cycles += 1
            sent, self._sent = self._sent, 0
            if not sent:
                return None

    def received(self, answer: Answer, now: float) -> None:
        """The answer to the request out (a frame, or why none came)."""
        run = self._out
        if run is None:
            return
        slot = run.slot
        told = False  # an Inputs or a Failed event tells the exchange itself
        for event in run.slave.feed(answer, now):
            update = None
            if isinstance(event, Inputs) and slot is not None:
                update = slot.feed(event.data)
                if update.garbled is not None:  # told before the exchange it came with
                    self.events.append((run, update.garbled))
            self.events.append((run, event))
            told = told or isinstance(event, Inputs | Failed)
            if update is not None and update.answer is not None:
                self.events.append((run, update.answer))
        if not told:
            self.events.append((run, StartupAnswered()))
        slave = run.slave
        if run.address in self._left_out:  # in maintenance meanwhile: nothing more to it
            self._pending = None
            return
        self._pending = slave.repeat_acyclic() if self._acyclic_out else slave.poll_acyclic()

    def take_events(self) -> list[tuple[SlaveRun, CycleEvent]]:
        events, self.events = self.events, []
        return events

    def leave_out(self, setup: SlaveSetup, slot: PkwSlot | None, out: bool) -> None:
        """Send the slave nothing from now on (its watchdog, where it has one, expires and
        it leaves data exchange by itself), or take it back, started afresh: diagnosis,
        parameters and configuration, then data exchange."""
        if out:
            self._left_out.add(setup.address)
            out_now = self._out
            if out_now is not None and out_now.address == setup.address:
                self._pending = None  # its record transfer's next request: never sent
        elif setup.address in self._left_out:
            self._left_out.discard(setup.address)
            self.runs[setup.address] = SlaveRun(DpSlave(setup), slot)

    def restart(self, runs: Sequence[tuple[SlaveSetup, PkwSlot | None]]) -> None:
        """Every slave afresh (the port was lost): the cycle begins again."""
        for setup, slot in runs:
            self.runs[setup.address] = SlaveRun(DpSlave(setup), slot)
        self._next = self._sent = 0
        self._out, self._pending = None, None
