"""The DP master over the simulator's real ends (TCP and a pty): start-up, PKW jobs in each
dialect, lag, rejection, a restart mid-job, a slave owned by another master, another master
on the line. Every PPO-write on the wire has control word bit 10 = 0."""

from __future__ import annotations

import asyncio
import dataclasses
import gc
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import pytest

from pkwbus.link import PortError, PortSettings
from pkwbus.master.planning.outcomes import Answered, Outcome, Rejected
from pkwbus.master.wires.profibus.cycle import SlaveLocked
from pkwbus.master.wires.profibus.port import FdlPort, ForeignMaster
from pkwbus.protocol import pkw
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import (
    DpSlave,
    Failed,
    FailureKind,
    Inputs,
    NoAnswer,
    SlaveSetup,
    SlaveState,
    TransferEnded,
)
from pkwbus.protocol.profibus.dpv1.msac import C1_SAP, Dpv1Setup
from pkwbus.protocol.profibus.dpv1.transfer import RecordRead
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.protocol.profidrive.parameters import RECORD, ParameterAddress, ParameterRequest
from pkwbus.sim import SimTiming
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.profibus.line import DpSimulator
from tests.master.conftest import serve
from tests.master.wires.profibus.cycle_harness import CycleHarness, run_dp_job
from tests.master.wires.profibus.frame_log import FrameLog, fake_master, log_frames

MASTER = 2
SLOT = 0.02


def make_sim(addresses: list[int], dialect: str, **kw: Any) -> DpSimulator:
    kw.setdefault("timing", SimTiming(response_delay=0.0))
    return DpSimulator(addresses, dialect=dialect, seed=11, **kw)


def setup_for(sim: DpSimulator, address: int, master: int = MASTER) -> SlaveSetup:
    prm = dps.Parameters(sim.ident, dps.watchdog_factors(2.0))
    return SlaveSetup(address, master, prm, sim.ppo.cfg, retries=2)


@asynccontextmanager
async def dp_master(
    sim: DpSimulator, end: str, addresses: list[int]
) -> AsyncIterator[tuple[CycleHarness, FrameLog]]:
    wire = log_frames(sim)
    async with serve(sim, end) as port:  # type: ignore[arg-type]
        line = FdlPort(PortSettings(port, baudrate=19200), MASTER, slot_time=SLOT)
        slaves = [(setup_for(sim, a), ppo.PkwSlot(sim.ppo, sim.dialect)) for a in addresses]
        master = CycleHarness(line, slaves)
        await master.start(listen=0.02)
        try:
            yield master, wire
        finally:
            await master.stop()
    wire.assert_never_took_control(sim.ppo.length)


async def job(
    master: CycleHarness, address: int, request: pkw.PkwRequest, within: float = 3.0
) -> Outcome:
    deadline = asyncio.get_running_loop().time() + within
    return await run_dp_job(master, address, request, deadline=deadline)


def value(outcome: Outcome) -> int:
    assert isinstance(outcome, Answered), outcome
    assert isinstance(outcome.response, pkw.ValueResponse)
    return outcome.response.raw


# A read, a write, an array element and (profidrive) a parameter above 1999 (page index).
PLANS: dict[str, dict[str, Any]] = {
    "danfoss-pcv": {"read": 1613, "write": (341, 1234, pkw.Width.DWORD), "array": (1530, 1)},
    "profidrive": {"read": 1082, "write": (2000, 0x42200000, pkw.Width.DWORD), "array": (2110, 3)},
    "hitachi-sjpb": {"read": 1082, "write": (1120, 0x41400000, pkw.Width.DWORD), "array": (947, 1)},
}


@pytest.mark.parametrize("dialect", sorted(PLANS))
async def test_start_up_read_write_and_array_in_each_dialect(end: str, dialect: str) -> None:
    sim = make_sim([8], dialect)
    plan = PLANS[dialect]
    dia = sim.dialect
    async with dp_master(sim, end, [8]) as (master, wire):
        got = value(await job(master, 8, pkw.read(dia, plan["read"])))
        assert got == sim.drives[8].value(plan["read"])
        assert master.runs[8].slave.state is SlaveState.DATA_EXCHANGE
        pnu, raw, width = plan["write"]
        assert isinstance(await job(master, 8, pkw.write(dia, pnu, raw, width)), Answered)
        assert sim.drives[8].value(pnu) == raw
        assert value(await job(master, 8, pkw.read(dia, pnu))) == raw
        apnu, index = plan["array"]
        got = value(await job(master, 8, pkw.read(dia, apnu, index)))
        assert got == sim.drives[8].value(apnu, index)
    assert wire.set_prm() == {(8, MASTER): 1}  # one start-up, nothing else parametrised
    assert sim.slaves[8].clears == 1  # Global_Control Clear at stop


async def test_the_page_index_reaches_the_drive_in_the_profidrive_dialect(end: str) -> None:
    sim = make_sim([8], "profidrive")
    async with dp_master(sim, end, [8]) as (master, wire):
        got = value(await job(master, 8, pkw.read(sim.dialect, 2000)))
        assert got == sim.drives[8].value(2000)
    pkw_of = [f.data[:8] for f in wire.data_exchanges()]
    # PNU 2000 goes as 2000 - 2000 with the page bit in IND's low byte (PROFIdrive layout).
    assert any(d[:2] != b"\x00\x00" and d[3] & 0x80 for d in pkw_of), [d.hex() for d in pkw_of]


async def test_a_lagging_answer_is_waited_for(end: str) -> None:
    sim = make_sim([8], "danfoss-pcv", timing=SimTiming(response_delay=0.0, lag_telegrams=4))
    async with dp_master(sim, end, [8]) as (master, _):
        outcome = await job(master, 8, pkw.read(sim.dialect, 341))
        assert value(outcome) == sim.drives[8].value(341)
    assert sim.drives[8].lagged >= 4


async def test_a_rejection_carries_the_dialect_s_fault_text(end: str) -> None:
    sim = make_sim([8], "danfoss-pcv")
    async with dp_master(sim, end, [8]) as (master, _):
        outcome = await job(master, 8, pkw.read(sim.dialect, 999))
    assert isinstance(outcome, Rejected)
    assert outcome.fault == 0 and outcome.text == "Illegal PNU"


async def test_a_slave_that_restarts_mid_job_still_finishes_the_job(end: str) -> None:
    sim = make_sim([8], "profidrive", timing=SimTiming(response_delay=0.0, lag_telegrams=3))
    answer = sim.answer
    exchanges = 0

    def restart_once(frame: object, now: float | None = None) -> Any:
        nonlocal exchanges
        if isinstance(frame, fdl.DataFrame) and frame.dsap is None and frame.data:
            exchanges += 1
            if exchanges == 3:  # the job's request is out, its answer lags
                sim.restart(8)
        return answer(frame, now)

    sim.answer = restart_once  # type: ignore[method-assign]
    async with dp_master(sim, end, [8]) as (master, wire):
        restarts: list[object] = []
        master.on_event = lambda _a, e: restarts.append(e)
        raw = 0x41A00000  # 20.0
        outcome = await job(master, 8, pkw.write(sim.dialect, 1120, raw, pkw.Width.DWORD))
        assert isinstance(outcome, Answered)
        assert sim.drives[8].value(1120) == raw
    assert sim.stats.injected["restart"] == 1
    assert wire.set_prm()[(8, MASTER)] == 2  # parametrised again after the restart


async def test_a_slave_owned_by_another_master_is_never_parametrised(end: str) -> None:
    sim = make_sim([8], "danfoss-pcv")
    # Master 1 parametrises the slave with lock first.
    other = DpSlave(setup_for(sim, 8, master=1))
    for n in range(4):
        frame = other.poll(n * 0.01)
        assert frame is not None
        raw = sim.handle(fdl.encode(frame))
        other.feed(NoAnswer() if raw is None else fdl.decode(raw), n * 0.01)
    assert sim.slaves[8].owner == 1
    wire = log_frames(sim)
    async with serve(sim, end) as port:  # type: ignore[arg-type]
        line = FdlPort(PortSettings(port, baudrate=19200), MASTER, slot_time=SLOT)
        master = CycleHarness(line, [(setup_for(sim, 8), ppo.PkwSlot(sim.ppo, sim.dialect))])
        await master.start(listen=0.02)
        try:
            with pytest.raises(SlaveLocked, match="owned by master 1"):
                await job(master, 8, pkw.write(sim.dialect, 341, 1, pkw.Width.DWORD))
        finally:
            await master.stop()
    assert wire.set_prm()[(8, MASTER)] == 0
    assert not wire.data_exchanges()
    assert all(f.dsap in (dps.Service.SLAVE_DIAG, dps.Service.GLOBAL_CONTROL) for f in wire.frames)
    assert sim.slaves[8].owner == 1


async def test_another_master_on_the_line_is_refused_before_anything_is_sent() -> None:
    async with fake_master() as fake:
        line = FdlPort(PortSettings(fake.url, baudrate=19200), MASTER, slot_time=SLOT)
        master = CycleHarness(line, [])
        with pytest.raises(ForeignMaster, match=r"another master is active.*station 1"):
            await master.start()
        await asyncio.sleep(0.05)
        assert fake.received == b""
        assert not line.is_open


async def test_another_master_heard_is_forgotten_when_the_port_fails() -> None:
    """The port's own state, not its wire's: another master heard refuses every request
    until the port fails (the runner gives it up), then it is listened for afresh."""
    async with fake_master() as fake:
        line = FdlPort(PortSettings(fake.url, baudrate=19200), MASTER, slot_time=SLOT)
        await line.open()
        try:
            with pytest.raises(ForeignMaster):
                await line.started()
            assert line.foreign is not None
            with pytest.raises(ForeignMaster):  # nothing goes out while it is heard
                await line.exchange(
                    fdl.DataFrame(8, MASTER, fdl.request_fc(fdl.Function.FDL_STATUS))
                )
            line.link.abort("another master is active")
            assert line.foreign is None
        finally:
            await line.close()
        assert fake.received == b""


@pytest.mark.parametrize("clear", [True, False])
async def test_the_port_of_a_lines_master_clears_its_slaves_as_it_closes(clear: bool) -> None:
    """Made ``clear_on_close`` (the DP line's master), the port sends Global_Control Clear
    before it closes; made without (the live list's), it only closes."""
    sim = make_sim([8], "danfoss-pcv")
    wire = log_frames(sim)
    async with serve(sim, "tcp") as port:  # type: ignore[arg-type]
        settings = PortSettings(port, baudrate=19200)
        line = FdlPort(settings, MASTER, slot_time=SLOT, clear_on_close=clear)
        await line.open()
        await line.exchange(fdl.DataFrame(8, MASTER, fdl.request_fc(fdl.Function.FDL_STATUS)))
        await line.close()
        assert not line.is_open
    cleared = [f for f in wire.frames if f.dsap == dps.Service.GLOBAL_CONTROL]
    assert [(f.da, f.sa) for f in cleared] == ([(fdl.BROADCAST, MASTER)] if clear else [])


def test_the_idle_times_and_the_slot_time_follow_the_baud_rate() -> None:
    line = FdlPort(PortSettings("/dev/null", baudrate=19200, parity="N"), MASTER)
    assert line.settings.parity == "E"
    assert line.settings.start_pause == pytest.approx(37 / 19200)
    assert line.slot_time == pytest.approx(0.030)
    assert FdlPort(PortSettings("/dev/null", baudrate=93750), MASTER).slot_time == pytest.approx(
        0.008
    )
    assert line.token_lost_time() == pytest.approx((6 + 2 * MASTER) * 0.030)
    # A Data_Exchange of PPO 1 (21 bytes each way) at 19200: about 28 ms.
    assert dp_timing.exchange_time(21, 21, 19200) == pytest.approx((42 * 11 + 81) / 19200)


async def test_a_late_answer_of_one_slave_is_not_taken_for_the_next_slaves(end: str) -> None:
    """One answer of slave 8 misses its slot time and reaches the line just before slave 9's
    answer: it is not 9's answer (its source address says so), and 9 sees no error."""
    sim = make_sim([8, 9], "danfoss-pcv")
    answer = sim.answer
    held: list[bytes] = []
    armed = False

    def late_once(frame: object, now: float | None = None) -> Answer | None:
        nonlocal armed
        result = answer(frame, now)
        exchange = isinstance(frame, fdl.DataFrame) and frame.dsap is None and bool(frame.data)
        if exchange and armed and result is not None:
            assert isinstance(frame, fdl.DataFrame)
            if frame.da == 8:
                armed = False
                held.append(result.data)
                return None  # 8's answer comes later ...
        if exchange and held and result is not None:
            assert isinstance(frame, fdl.DataFrame) and frame.da == 9
            return Answer(held.pop() + result.data)  # ... right before 9's
        return result

    sim.answer = late_once  # type: ignore[method-assign]
    async with dp_master(sim, end, [8, 9]) as (master, _):
        events: list[tuple[int, object]] = []
        master.on_event = lambda address, event: events.append((address, event))
        while not all(r.slave.state is SlaveState.DATA_EXCHANGE for r in master.runs.values()):
            await master.cycle()
        events.clear()
        armed = True
        for _ in range(4):
            await master.cycle()
    assert not armed and not held
    failures = [(a, e) for a, e in events if isinstance(e, Failed)]
    assert [(a, e.kind) for a, e in failures] == [(8, FailureKind.TIMEOUT)]
    assert sum(1 for a, e in events if a == 9 and isinstance(e, Inputs)) == 4


async def test_a_port_lost_while_the_request_goes_out_leaves_no_unretrieved_error(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The loss is raised by the request's own send; the answer's waiter, which the loss
    also ended, is not left with an error nobody reads (asyncio would log it)."""
    caplog.set_level(logging.ERROR, logger="asyncio")
    line = FdlPort(PortSettings("socket://127.0.0.1:9", baudrate=19200), MASTER, slot_time=SLOT)

    async def lost_while_sending(raw: bytes) -> None:
        line._on_lost("lost socket://127.0.0.1:9: the port was closed at its other end")
        raise PortError("socket://127.0.0.1:9 is not open")

    line.link.send = lost_while_sending  # type: ignore[method-assign]
    frame = fdl.DataFrame(8, MASTER, fdl.request_fc(fdl.Function.SRD_HIGH), data=b"\x00")
    with pytest.raises(PortError):
        await line.exchange(frame)
    gc.collect()
    await asyncio.sleep(0)
    assert "never retrieved" not in caplog.text


async def test_an_unanswered_record_request_is_repeated_at_once_and_data_exchange_goes_on(
    end: str,
) -> None:
    # The FDL repeats a request right after its slot time: a repeat of the MSAC_C1
    # request must not take the place of the slave's next Data_Exchange.
    sim = make_sim([8], "profidrive", ppo_number=3, dpv1=True)
    answer = sim.answer
    dropped: list[fdl.DataFrame] = []

    def drop_the_first_record_request(frame: object, now: float | None = None) -> Any:
        if isinstance(frame, fdl.DataFrame) and frame.dsap == C1_SAP and not dropped:
            dropped.append(frame)
            return None
        return answer(frame, now)

    sim.answer = drop_the_first_record_request  # type: ignore[method-assign]
    wire = log_frames(sim)  # sees every request, the dropped one too
    ended: list[TransferEnded] = []

    def on_event(address: int, event: object) -> None:
        if isinstance(event, TransferEnded):
            ended.append(event)

    async with serve(sim, end) as port:
        line = FdlPort(PortSettings(port, baudrate=19200), MASTER, slot_time=SLOT)
        setup = dataclasses.replace(setup_for(sim, 8), dpv1=Dpv1Setup(response_timeout=2.0))
        master = CycleHarness(line, [(setup, None)], on_event=on_event)
        await master.start(listen=0.02)
        try:
            slave = master.runs[8].slave
            for _ in range(50):
                if slave.state is SlaveState.DATA_EXCHANGE:
                    break
                await master.cycle()
            assert slave.state is SlaveState.DATA_EXCHANGE
            request = ParameterRequest.read(1, 1, [ParameterAddress(2)])
            slave.start_transfer(0, RECORD, request.encode(), asyncio.get_running_loop().time())
            wire.frames.clear()
            cycles = 0
            while not ended and cycles < 50:
                await master.cycle()
                cycles += 1
        finally:
            await master.stop()
    assert len(dropped) == 1 and ended and isinstance(ended[0].end, RecordRead)
    to_slave = [f for f in wire.frames if f.da == 8]
    exchanges = [f for f in to_slave if f.dsap is None]
    assert len(exchanges) == cycles  # a Data_Exchange every cycle, the repeat's too
    first = to_slave.index(dropped[0])
    repeat = to_slave[first + 1]  # right after the unanswered one, the same FCB
    assert repeat.dsap == C1_SAP and repeat.data == dropped[0].data
    assert repeat.control == dropped[0].control
