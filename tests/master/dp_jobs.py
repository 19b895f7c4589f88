"""One job on a started DpMaster, through its slave's start-up and PKW slot: the DP
master's own test harness (the command line and the service run jobs through the line
runner, :mod:`pkwbus.master.single_job`)."""

from __future__ import annotations

import asyncio

from pkwbus.link import PortError
from pkwbus.master.dp_master import DpMaster, SlaveLocked
from pkwbus.master.outcomes import Answered, LineFailed, Mismatch, Outcome, Rejected, TimedOut
from pkwbus.protocol import pkw
from pkwbus.protocol.dp_slave import Failed, FailureKind, SlaveEvent, SlaveState, StateChanged
from pkwbus.protocol.ppo import JobDone, JobExpired, SlotResult


def outcome_of(result: SlotResult) -> Outcome:
    """What a slot's finished job comes to, as for FC and USS jobs."""
    if isinstance(result, JobExpired):
        return TimedOut(f"no matching answer within the deadline ({result.cycles} cycles)")
    response, request = result.response, result.request
    if isinstance(response, pkw.Rejection):
        return Rejected(response.fault, response.text, response.short)
    if result.mismatch and isinstance(response, pkw.ValueResponse):
        return Mismatch(request.value, response.raw, response)
    return Answered(response)


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
    slot.submit(request, deadline)
    result: list[SlotResult] = []
    gone: list[str] = []
    hook = master.on_event

    def watch(addr: int, event: SlaveEvent | SlotResult) -> None:
        if hook is not None:
            hook(addr, event)
        if addr != address:
            return
        if isinstance(event, JobDone | JobExpired):
            result.append(event)
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
                expired = slot.expire(loop.time())
                return outcome_of(expired) if expired else TimedOut("deadline passed")
            try:
                await master.cycle()
            except PortError as exc:
                return LineFailed(str(exc))
        return outcome_of(result[0])
    finally:
        master.on_event = hook
