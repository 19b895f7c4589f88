"""Simulated PROFIBUS DP slaves on a line: the master's state machine and PKW slot against
them, in process and over the TCP and pty ends, with the DP faults."""

from __future__ import annotations

import asyncio
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from pkwbus.protocol import pkw, pzd
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import (
    DpSlave,
    Inputs,
    NoAnswer,
    Restarted,
    SlaveSetup,
    SlaveState,
)
from pkwbus.sim.profibus.line import DEFAULT_IDENTS, DpFaults, DpSimulator

MASTER = 2
# A parameter of each dialect's drive, read through the PPO.
READS = {"danfoss-pcv": 1613, "profidrive": 1082, "hitachi-sjpb": 1082}


def master_for(sim: DpSimulator, address: int, watchdog: float = 1.0) -> DpSlave:
    prm = dps.Parameters(sim.ident, dps.watchdog_factors(watchdog))
    return DpSlave(SlaveSetup(address, MASTER, prm, sim.ppo.cfg))


def ctw_of(request: bytes) -> int:
    """The control word of a PPO-write inside a Data_Exchange request frame on the wire."""
    frame = fdl.decode(request)
    assert isinstance(frame, fdl.DataFrame)
    return int.from_bytes(frame.data[8:10], "big")


class Wire:
    """The master's side, frame by frame through the wire format; every request kept."""

    def __init__(self, sim: DpSimulator, address: int) -> None:
        self.sim, self.address = sim, address
        self.master = master_for(sim, address)
        self.slot = ppo.PkwSlot(sim.ppo, sim.dialect)
        self.sent: list[bytes] = []
        self.events: list[object] = []

    def cycle(self, now: float) -> None:
        outputs = self.slot.outputs() if self.master.state is SlaveState.DATA_EXCHANGE else None
        frame = self.master.poll(now, outputs)
        assert frame is not None
        raw = fdl.encode(frame)
        self.sent.append(raw)
        answer = self.sim.handle(raw)
        reply = NoAnswer() if answer is None else fdl.decode(answer)
        for event in self.master.feed(reply, now):
            self.events.append(event)
            if isinstance(event, Inputs) and self.master.state is SlaveState.DATA_EXCHANGE:
                update = self.slot.feed(event.data)
                answer = update.answer  # judged by the one rule of every bus
                if answer is not None and pkw.judge(
                    answer.request, answer.response, self.sim.dialect
                ) is pkw.Verdict.ANSWER:  # fmt: skip
                    self.events.append(answer)
                    self.slot.finish()

    def data_exchange_requests(self) -> list[bytes]:
        out = []
        for raw in self.sent:
            frame = fdl.decode(raw)
            if isinstance(frame, fdl.DataFrame) and frame.dsap is None and frame.data:
                out.append(raw)
        return out


@pytest.mark.parametrize("dialect", sorted(READS))
def test_each_dialect_starts_up_and_answers_a_read(dialect: str) -> None:
    sim = DpSimulator([8], dialect=dialect, seed=1, clock=lambda: 0.0)
    assert sim.ident == DEFAULT_IDENTS[dialect]
    wire = Wire(sim, 8)
    now = 0.0
    for _ in range(4):
        wire.cycle(now)
        now += 0.01
    assert wire.master.state is SlaveState.DATA_EXCHANGE
    pnu = READS[dialect]
    wire.slot.submit(pkw.read(sim.dialect, pnu))
    for _ in range(30):
        wire.cycle(now)
        now += 0.01
    done = [e for e in wire.events if isinstance(e, ppo.SlotAnswer)]
    assert len(done) == 1
    assert isinstance(done[0].response, pkw.ValueResponse)
    assert done[0].response.raw == sim.drives[8].value(pnu)
    exchanges = wire.data_exchange_requests()
    assert exchanges and all(not pzd.takes_control(ctw_of(r)) for r in exchanges)
    assert sim.drives[8].control_taken == 0


def test_a_write_through_the_ppo_changes_the_drive() -> None:
    sim = DpSimulator([9], dialect="danfoss-pcv", seed=2)
    wire = Wire(sim, 9)
    now = 0.0
    for _ in range(4):
        wire.cycle(now)
        now += 0.01
    wire.slot.submit(pkw.write(sim.dialect, 341, 1234, pkw.Width.DWORD))
    for _ in range(30):
        wire.cycle(now)
        now += 0.01
    assert [e for e in wire.events if isinstance(e, ppo.SlotAnswer)]
    assert sim.drives[9].value(341) == 1234


def test_a_restart_sends_the_master_through_set_prm_again() -> None:
    sim = DpSimulator([8], seed=3)
    wire = Wire(sim, 8)
    now = 0.0
    for _ in range(4):
        wire.cycle(now)
        now += 0.01
    assert wire.master.state is SlaveState.DATA_EXCHANGE
    sim.restart(8)
    for _ in range(8):
        wire.cycle(now)
        now += 0.01
    assert any(isinstance(e, Restarted) for e in wire.events)
    assert wire.master.state is SlaveState.DATA_EXCHANGE
    assert sim.stats.injected["restart"] == 1


def test_an_injected_rs_answer_restarts_the_slave_s_set_up() -> None:
    sim = DpSimulator([8], seed=4)
    wire = Wire(sim, 8)
    now = 0.0
    for _ in range(4):
        wire.cycle(now)
        now += 0.01
    sim.faults = DpFaults(rs=1.0)
    wire.cycle(now)
    assert any(isinstance(e, Restarted) and e.reason.value == "rs" for e in wire.events)
    sim.faults = DpFaults()
    for _ in range(8):
        now += 0.01
        wire.cycle(now)
    assert wire.master.state is SlaveState.DATA_EXCHANGE


def status_request(address: int) -> bytes:
    return fdl.encode(fdl.DataFrame(address, MASTER, fdl.request_fc(fdl.Function.FDL_STATUS)))


def test_a_corrupt_answer_has_a_bad_fcs_and_a_dead_slave_is_silent() -> None:
    sim = DpSimulator([8, 9], seed=5, faults=DpFaults(dead=frozenset({9})))
    clean = sim.handle(status_request(8))
    assert clean is not None
    (answer,) = [e for e in fdl.Deframer().feed(clean) if isinstance(e, fdl.Frame)]
    assert isinstance(answer, fdl.DataFrame)
    assert answer.control.status is fdl.Status.OK  # FDL status: a slave is at 8
    assert answer.control.station_type is fdl.StationType.SLAVE
    assert sim.handle(status_request(9)) is None  # dead
    sim.faults = DpFaults(corrupt=1.0)
    corrupt = sim.handle(status_request(8))
    assert corrupt is not None and len(corrupt) == len(clean) and corrupt != clean
    assert not any(isinstance(e, fdl.Frame) for e in fdl.Deframer().feed(corrupt))
    assert sim.handle(status_request(9)) is not None  # revived with the new faults


@pytest.mark.parametrize("kind", ["corrupt", "rs"])
def test_a_corrupt_or_rs_fault_is_counted_only_where_it_can_be_made(kind: str) -> None:
    """The short acknowledge (to Set_Prm) has no FCS and no status: it goes out clean and
    the stats do not count a fault that did not happen; the next data frame gets it."""
    sim = DpSimulator([8], dialect="danfoss-pcv", seed=5, faults=DpFaults(**{kind: 1.0}))
    prm = dps.Parameters(sim.ident, dps.watchdog_factors(1.0)).encode()
    set_prm = dps.request(dps.Service.SET_PRM, 8, MASTER, prm, fcb=True, fcv=False)
    assert sim.handle(fdl.encode(set_prm)) == fdl.encode(fdl.ShortAck())
    assert sim.stats.injected[kind] == 0
    diag = dps.request(dps.Service.SLAVE_DIAG, 8, MASTER, b"", fcb=False, fcv=True)
    raw = sim.handle(fdl.encode(diag))
    assert raw is not None
    frames = [e for e in fdl.Deframer().feed(raw) if isinstance(e, fdl.Frame)]
    if kind == "corrupt":
        assert not frames
    else:
        (frame,) = frames
        assert isinstance(frame, fdl.DataFrame) and frame.control.status is fdl.Status.RS
    assert sim.stats.injected[kind] == 1


def test_bad_options_are_refused() -> None:
    with pytest.raises(ValueError, match="not used over PROFIBUS"):
        DpSimulator([8], dialect="fc")
    with pytest.raises(ValueError, match="0-125"):
        DpSimulator([126])
    with pytest.raises(ValueError, match="add up"):
        DpFaults(rs=0.6, restart=0.6)


async def test_over_tcp_and_a_pty() -> None:
    sim = DpSimulator([8], dialect="danfoss-pcv", seed=6)
    tcp = await sim.serve_tcp("127.0.0.1", 0)
    with tempfile.TemporaryDirectory() as tmp:
        pty = await sim.serve_pty(str(Path(tmp) / "ttyDP"))
        try:
            reader, writer = await asyncio.open_connection(tcp.host, tcp.port)
            m = master_for(sim, 8)
            for n in range(4):
                frame = m.poll(n * 0.01)
                assert frame is not None
                writer.write(fdl.encode(frame))
                answer = await asyncio.wait_for(_one_frame(reader), 5)
                m.feed(answer, n * 0.01)
            assert m.state is SlaveState.DATA_EXCHANGE
            writer.close()
            assert Path(pty.path).exists()
        finally:
            await pty.close()
            await tcp.close()


async def _one_frame(reader: asyncio.StreamReader) -> fdl.Frame:
    deframer = fdl.Deframer()
    while True:
        for event in deframer.feed(await reader.read(256)):
            if isinstance(event, fdl.Frame):
                return event


def test_simulate_profibus_on_the_command_line() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "pkwbus", "simulate", "--protocol", "profibus",
         "--listen", "tcp://127.0.0.1:0", "--drives", "8,9", "--dialect", "danfoss-pcv"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert "profibus slaves 8,9 (danfoss-pcv, PPO 1, ident 0x0402)" in line, line
    finally:
        proc.terminate()
        proc.wait(10)
    refused = subprocess.run(
        [sys.executable, "-m", "pkwbus", "simulate", "--protocol", "profibus",
         "--listen", "tcp://127.0.0.1:0", "--truncate", "0.1"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert refused.returncode == 2 and "not a PROFIBUS fault" in refused.stderr
