"""One job on a started DpMaster, through its slave's start-up and PKW slot: the DP
master's own test harness (the command line and the service run jobs through the line
runner, :mod:`pkwbus.master.sessions.jobs`)."""

from __future__ import annotations

import asyncio

from pkwbus.link import PortError
from pkwbus.master.carriers import SlotCarrier
from pkwbus.master.planning.answers import PkwAnswer
from pkwbus.master.planning.carrier import Item
from pkwbus.master.planning.outcomes import LineFailed, Outcome, TimedOut
from pkwbus.master.wires.profibus.cycle import DpMaster, SlaveLocked
from pkwbus.protocol import pkw
from pkwbus.protocol.profibus.dp.ppo import SlotAnswer
from pkwbus.protocol.profibus.dp.slave import (
    Failed,
    FailureKind,
    SlaveEvent,
    SlaveState,
    StateChanged,
)


async def run_dp_job(
    master: DpMaster, address: int, request: pkw.PkwRequest, *, deadline: float
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
    tx = carrier.transaction([Item(request)], retries=0, deadline=deadline)
    slot.submit(request)
    result: list[Outcome] = []
    gone: list[str] = []
    hook = master.on_event

    def watch(addr: int, event: SlaveEvent | SlotAnswer) -> None:
        if hook is not None:
            hook(addr, event)
        if addr != address:
            return
        if isinstance(event, SlotAnswer):
            answer = PkwAnswer(event.response, b"", None, None, 0.0, cyclic=True,
                               earlier=event.earlier)  # fmt: skip
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
