"""The simulated DP slave against the master's state machine and PKW slot, frame by frame."""

from __future__ import annotations

import random

from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.dialects import IndLayout
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import DpSlave, Inputs, NoAnswer, SlaveSetup, SlaveState
from pkwbus.protocol.serial.telegram import BlockShape
from pkwbus.sim.config import SimTiming
from pkwbus.sim.drives.drive import SimDrive
from pkwbus.sim.drives.table import TABLES
from pkwbus.sim.profibus.slave import SimDpSlave, SlaveMode

MASTER, ADDRESS, IDENT = 2, 8, 0x80B5
PPO1 = ppo.ppo_type(1)
DIALECT = ppo.dp_dialect("profidrive")


def make_slave() -> tuple[SimDpSlave, SimDrive]:
    drive = SimDrive(
        ADDRESS, Bus.USS, DIALECT, IndLayout.PROFIDRIVE, BlockShape(4, 2),
        TABLES[Bus.USS], SimTiming(), random.Random(1),
    )  # fmt: skip
    return SimDpSlave(ADDRESS, IDENT, PPO1.cfg, drive.respond), drive


def master(watchdog: float = 0.5) -> DpSlave:
    prm = dps.Parameters(IDENT, dps.watchdog_factors(watchdog))
    return DpSlave(SlaveSetup(ADDRESS, MASTER, prm, PPO1.cfg))


def exchange(m: DpSlave, s: SimDpSlave, now: float, outputs: bytes | None = None) -> list[object]:
    frame = m.poll(now, outputs)
    assert frame is not None
    # Through the wire format both ways.
    answer = s.handle(fdl.decode(fdl.encode(frame)), now)
    reply = NoAnswer() if answer is None else fdl.decode(fdl.encode(answer))
    return list(m.feed(reply, now))


def test_start_up_into_data_exchange() -> None:
    slave, _ = make_slave()
    m = master()
    for n in range(4):
        exchange(m, slave, n * 0.01)
    assert m.state is SlaveState.DATA_EXCHANGE and slave.mode is SlaveMode.DATA_EXCH
    assert slave.owner == MASTER and slave.watchdog is not None


def test_a_parameter_read_through_the_ppo() -> None:
    slave, drive = make_slave()
    m = master()
    slot = ppo.PkwSlot(PPO1, DIALECT)
    now = 0.0
    for _ in range(4):
        exchange(m, slave, now)
    request = pkw.read(DIALECT, 304)
    slot.submit(request)
    done = None
    for _ in range(20):
        now += 0.01
        events = exchange(m, slave, now, slot.outputs())
        for event in events:
            if isinstance(event, Inputs):
                answer = slot.feed(event.data).answer
                if answer and pkw.judge(request, answer.response, DIALECT) is pkw.Verdict.ANSWER:
                    done = done or answer
        if done:
            break
    assert isinstance(done, ppo.SlotAnswer)
    assert isinstance(done.response, pkw.ValueResponse)
    assert done.response.raw == drive.value(304)
    assert drive.control_taken == 0


def test_watchdog_sends_the_slave_back_and_the_master_restarts_it() -> None:
    slave, _ = make_slave()
    m = master(watchdog=0.2)
    for _ in range(4):
        exchange(m, slave, 0.0)
    slave.tick(0.3)
    assert slave.mode is SlaveMode.WAIT_PRM and slave.timeouts == 1
    for n in range(6):
        exchange(m, slave, 0.3 + n * 0.01)
    assert m.state is SlaveState.DATA_EXCHANGE


def test_a_slave_owned_by_another_master_is_not_parametrised() -> None:
    slave, _ = make_slave()
    other = DpSlave(SlaveSetup(ADDRESS, 3, dps.Parameters(IDENT, (100, 100)), PPO1.cfg))
    for _ in range(4):
        exchange(other, slave, 0.0)
    assert slave.owner == 3
    m = master()
    exchange(m, slave, 0.0)
    assert m.state is SlaveState.LOCKED and slave.owner == 3


def test_a_retry_gets_the_previous_answer() -> None:
    slave, _ = make_slave()
    m = master()
    frame = m.poll(0.0)
    assert frame is not None
    first = slave.handle(frame, 0.0)
    m.feed(NoAnswer(), 0.0)  # lost on the way back
    again = m.poll(0.0)
    assert again == frame
    assert slave.handle(again, 0.0) == first


def test_wrong_configuration_is_a_cfg_fault() -> None:
    slave, _ = make_slave()
    prm = dps.Parameters(IDENT, dps.watchdog_factors(0.5))
    m = DpSlave(SlaveSetup(ADDRESS, MASTER, prm, ppo.ppo_type(2).cfg))
    for _ in range(4):
        exchange(m, slave, 0.0)
    assert slave.cfg_fault and m.state is not SlaveState.DATA_EXCHANGE
    assert "cfg_fault" in slave.diagnosis().flags
