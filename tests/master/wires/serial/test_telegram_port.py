"""One line's PKW exchanges against simulated drives, over TCP and a pty."""

from __future__ import annotations

import asyncio
import struct
from pathlib import Path
from typing import Any

import pytest

from pkwbus.link import PortSettings
from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.planning.answers import ErrorKind, Failure
from pkwbus.master.planning.outcomes import Answered, LineFailed, Rejected, TimedOut
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.dialects import IndLayout
from pkwbus.protocol.pzd import takes_control
from pkwbus.protocol.values import Scaling, ValueType, encode_value
from pkwbus.sim import SimFaults, SimTiming
from tests.master.conftest import make_sim, open_port, run_job, serve


def value(outcome: object) -> int:
    assert isinstance(outcome, Answered), outcome
    assert isinstance(outcome.response, pkw.ValueResponse)
    return outcome.response.raw


async def test_fc_read_matches_the_drive(end: str) -> None:
    sim = make_sim("fc", [1, 7])
    sim.drives[7].set_value(341, 1234)
    sim.drives[1].set_value(341, 999)
    target = DriveTarget.create("fc", 7)
    async with serve(sim, end) as port, open_port(port, "fc") as (line, trace):
        raw = value(await run_job(line, target, pkw.read(target.dialect, 341)))
        assert raw == 1234
        current = value(await run_job(line, target, pkw.read(target.dialect, 1614)))
        assert 0 <= current < 100_000  # a live value with noise: plausible, from drive 7
        assert trace.tx and all(not takes_control(t[-5] << 8 | t[-4]) for t in trace.tx)
    assert sim.drives[7].control_taken == 0


@pytest.mark.parametrize(("pnu", "vtype"), [(414, ValueType.U16), (341, ValueType.U32)])
@pytest.mark.parametrize("store", list(pkw.Store))
async def test_fc_writes_word_and_double_word_to_ram_and_eeprom(
    pnu: int, vtype: ValueType, store: pkw.Store
) -> None:
    sim = make_sim("fc", [3])
    target = DriveTarget.create("fc", 3)
    raw = encode_value(123.4, vtype, Scaling.conversion(-1))
    width = vtype.width
    assert width is not None
    async with serve(sim, "tcp") as port, open_port(port, "fc") as (line, _):
        req = pkw.write(target.dialect, pnu, raw, width, store=store)
        assert value(await run_job(line, target, req)) == raw
    assert sim.drives[3].value(pnu) == raw
    assert ((pnu, 0) in sim.drives[3].eeprom) is (store is pkw.Store.EEPROM)


async def test_a_word_write_to_a_double_word_parameter_is_rejected() -> None:
    sim = make_sim("fc", [3])
    target = DriveTarget.create("fc", 3)
    before = sim.drives[3].value(341)
    async with serve(sim, "tcp") as port, open_port(port, "fc") as (line, _):
        outcome = await run_job(line, target, pkw.write(target.dialect, 341, 7, pkw.Width.WORD))
    assert isinstance(outcome, Rejected) and outcome.fault == 5
    assert sim.drives[3].value(341) == before


@pytest.mark.parametrize("layout", list(IndLayout))
async def test_uss_index_and_page_in_both_layouts(end: str, layout: IndLayout) -> None:
    sim = make_sim("uss", [2], ind_layout=layout)
    target = DriveTarget.create("uss", 2, ind_layout=layout)
    async with serve(sim, end) as port, open_port(port, "uss") as (line, trace):
        raw = value(await run_job(line, target, pkw.read(target.dialect, 947, 3)))
        assert raw == sim.drives[2].value(947, 3)
        ind = int.from_bytes(trace.tx[0][5:7], "big")
        assert ind == (3 if layout is IndLayout.USS else 3 << 8)
        trace.tx.clear()
        raw = value(await run_job(line, target, pkw.read(target.dialect, 2000)))
        assert raw == sim.drives[2].value(2000) == encode_value(50.0, ValueType.F32)
        pke, ind = int.from_bytes(trace.tx[0][3:5], "big"), int.from_bytes(trace.tx[0][5:7], "big")
        assert pke & 0x7FF == 0  # 2000 = page offset 2000 + 0
        assert ind == (0x8000 if layout is IndLayout.USS else 0x0080)


async def test_uss_float_write_and_read_back() -> None:
    sim = make_sim("uss", [1])
    target = DriveTarget.create("uss", 1)
    bits = encode_value(42.5, ValueType.F32)
    async with serve(sim, "tcp") as port, open_port(port, "uss") as (line, _):
        write = pkw.write(target.dialect, 1082, bits, pkw.Width.DWORD)
        assert value(await run_job(line, target, write)) == bits
        raw = value(await run_job(line, target, pkw.read(target.dialect, 1082)))
    assert struct.unpack(">f", raw.to_bytes(4, "big"))[0] == 42.5


@pytest.mark.parametrize(
    ("protocol", "pnu", "fault", "text"),
    [
        ("fc", 999, 0, "The parameter number used does not exit"),
        ("uss", 999, 0, "Illegal parameter number (PNU)"),
    ],
)
async def test_rejection_carries_the_dialects_text(
    protocol: str, pnu: int, fault: int, text: str
) -> None:
    sim = make_sim(protocol, [1])
    target = DriveTarget.create(protocol, 1)
    async with serve(sim, "tcp") as port, open_port(port, protocol) as (line, _):
        outcome = await run_job(line, target, pkw.read(target.dialect, pnu))
    assert isinstance(outcome, Rejected)
    assert (outcome.fault, outcome.text) == (fault, text)


@pytest.mark.parametrize("mode", ["none", "stale"])
async def test_repeat_rule_with_lag(end: str, mode: str) -> None:
    timing = SimTiming(response_delay=0.0, lag_telegrams=3, lag_mode=mode)  # type: ignore[arg-type]
    sim = make_sim("uss", [4], timing=timing)
    target = DriveTarget.create("uss", 4)
    async with serve(sim, end) as port, open_port(port, "uss") as (line, trace):
        await run_job(line, target, pkw.read(target.dialect, 1120))
        trace.tx.clear()
        outcome = await run_job(line, target, pkw.read(target.dialect, 1121))
    assert isinstance(outcome, Answered) and outcome.response.pnu == 1121
    assert value(outcome) == sim.drives[4].value(1121)
    assert len(trace.tx) >= 4, "the answer lagged: the request had to be repeated"
    assert len(set(trace.tx)) == 1, "every repeat sends the same bytes"


async def test_a_stale_answer_to_a_write_is_not_taken(end: str) -> None:
    timing = SimTiming(response_delay=0.0, lag_telegrams=2, lag_mode="stale")
    sim = make_sim("uss", [4], timing=timing)
    target = DriveTarget.create("uss", 4)
    new = encode_value(12.5, ValueType.F32)
    async with serve(sim, end) as port, open_port(port, "uss") as (line, trace):
        old = value(await run_job(line, target, pkw.read(target.dialect, 1120)))
        assert old != new
        trace.rx.clear()
        outcome = await run_job(line, target, pkw.write(target.dialect, 1120, new, pkw.Width.DWORD))
    assert value(outcome) == new
    assert old.to_bytes(4, "big") in b"".join(trace.rx), "the drive answered with the stale value"
    assert sim.drives[4].value(1120) == new


async def test_timeouts_are_retried_then_reported() -> None:
    sim = make_sim("fc", [1], faults=SimFaults(dead=frozenset({1})))
    target = DriveTarget.create("fc", 1)
    async with serve(sim, "tcp") as port, open_port(port, "fc", timeout=0.02) as (line, trace):
        outcome = await run_job(line, target, pkw.read(target.dialect, 1613), retries=2)
    assert isinstance(outcome, TimedOut)
    assert len(trace.tx) == 3


@pytest.mark.parametrize("fault", ["corrupt", "truncate", "garbage", "wrong_address", "drop"])
async def test_bad_answers_are_recovered_from(end: str, fault: str) -> None:
    faults = SimFaults(**{fault: 0.3})  # type: ignore[arg-type]
    sim = make_sim("fc", [1], faults=faults)
    target = DriveTarget.create("fc", 1)
    # A timeout long enough for a loaded machine: a late answer is not a fault recovered from.
    async with serve(sim, end) as port, open_port(port, "fc", timeout=0.2) as (line, _):
        for _ in range(10):
            outcome = await run_job(line, target, pkw.read(target.dialect, 1614), retries=10)
            assert isinstance(outcome, Answered), outcome
    assert sim.stats.as_dict()["injected"][fault] > 0


async def test_local_echo_is_stripped() -> None:
    sim = make_sim("fc", [5])
    target = DriveTarget.create("fc", 5)

    async def relay(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """An adapter that hears its own transmission: echo, then the bus's answer."""
        sim_reader, sim_writer = await asyncio.open_connection(host, sim_port)

        async def back() -> None:
            while data := await sim_reader.read(256):
                writer.write(data)

        task = asyncio.create_task(back())
        while data := await reader.read(256):
            writer.write(data)  # the echo
            sim_writer.write(data)
        task.cancel()
        sim_writer.close()
        writer.close()

    async with serve(sim, "tcp") as port:
        host, sim_port = port.removeprefix("socket://").split(":")
        server = await asyncio.start_server(relay, "127.0.0.1", 0)
        relay_port = server.sockets[0].getsockname()[1]
        url = f"socket://127.0.0.1:{relay_port}"
        async with open_port(url, "fc", echo=True) as (line, _):
            raw = value(await run_job(line, target, pkw.read(target.dialect, 1613)))
        server.close()
    assert raw == sim.drives[5].value(1613)


async def test_the_port_vanishes_mid_exchange_and_comes_back(end: str, tmp_path: Path) -> None:
    sim = make_sim("fc", [1], timing=SimTiming(response_delay=0.3))
    target = DriveTarget.create("fc", 1)
    server: Any = await (
        sim.serve_tcp("127.0.0.1", 0) if end == "tcp" else sim.serve_pty(str(tmp_path / "ttyGW"))
    )
    port = server.url if end == "tcp" else server.path
    settings = PortSettings(port, reopen_initial=0.05, reopen_cap=0.2)
    line = TelegramPort(settings, Bus.FC, timeout=1.0)
    await line.open()
    try:
        job = asyncio.create_task(run_job(line, target, pkw.read(target.dialect, 341)))
        await asyncio.sleep(0.1)  # the request is out, the answer is 0.2 s away
        await server.close()
        outcome = await asyncio.wait_for(job, 1.0)
        assert isinstance(outcome, LineFailed)
        assert not line.is_open and line.link.reconnect.last_error
        sim.timing = SimTiming(response_delay=0.0)
        if end == "tcp":
            server = await sim.serve_tcp("127.0.0.1", int(port.rsplit(":", 1)[1]))
        else:
            server = await sim.serve_pty(port)
        started = asyncio.get_running_loop().time()
        outcome = await run_job(line, target, pkw.read(target.dialect, 341))
        assert value(outcome) == sim.drives[1].value(341)
        assert asyncio.get_running_loop().time() - started < 1.0
    finally:
        await line.close()
        await server.close()


async def test_a_foreign_telegram_before_the_answer_is_not_taken_for_it() -> None:
    """A late answer to an earlier request (another ADR) arrives first: ours still counts."""
    sim = make_sim("fc", [1, 2])
    target = DriveTarget.create("fc", 1)
    other = DriveTarget.create("fc", 2)
    stray = sim.handle(SerialCarrier(other).telegram(pkw.read(other.dialect, 341)))
    assert stray is not None

    async def relay(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        sim_reader, sim_writer = await asyncio.open_connection(host, sim_port)
        while data := await reader.read(256):
            sim_writer.write(data)
            answer = await sim_reader.read(256)
            writer.write(stray + answer)  # drive 2's stale answer, then drive 1's
        sim_writer.close()
        writer.close()

    async with serve(sim, "tcp") as port:
        host, sim_port = port.removeprefix("socket://").split(":")
        server = await asyncio.start_server(relay, "127.0.0.1", 0)
        url = f"socket://127.0.0.1:{server.sockets[0].getsockname()[1]}"
        async with open_port(url, "fc") as (line, trace):
            outcome = await run_job(line, target, pkw.read(target.dialect, 341), retries=0)
        server.close()
    assert value(outcome) == sim.drives[1].value(341)
    assert len(trace.tx) == 1, "answered on the first try"


async def test_only_foreign_answers_end_as_an_address_error() -> None:
    sim = make_sim("fc", [1], faults=SimFaults(wrong_address=1.0))
    target = DriveTarget.create("fc", 1)
    async with serve(sim, "tcp") as port, open_port(port, "fc", timeout=0.05) as (line, _):
        result = await line.exchange(
            SerialCarrier(target).address,
            SerialCarrier(target).telegram(pkw.read(target.dialect, 341)),
        )
    assert isinstance(result, Failure) and result.kind is ErrorKind.ADDRESS


async def test_an_echo_is_not_taken_for_the_answer_when_echo_is_off(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """An adapter that hears itself on a line configured without echo: the echo of a
    read (AK 1, PWE 0) would otherwise pass for the drive's answer of 0."""
    sim = make_sim("fc", [5])
    sim.drives[5].set_value(341, 4321)
    target = DriveTarget.create("fc", 5)

    async def relay(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        sim_reader, sim_writer = await asyncio.open_connection(host, sim_port)
        while data := await reader.read(256):
            writer.write(data)  # the echo
            sim_writer.write(data)
            writer.write(await sim_reader.read(256))
        sim_writer.close()
        writer.close()

    async with serve(sim, "tcp") as port:
        host, sim_port = port.removeprefix("socket://").split(":")
        server = await asyncio.start_server(relay, "127.0.0.1", 0)
        url = f"socket://127.0.0.1:{server.sockets[0].getsockname()[1]}"
        async with open_port(url, "fc") as (line, _):
            raw = value(await run_job(line, target, pkw.read(target.dialect, 341), retries=0))
        server.close()
    assert raw == 4321
    assert any("echoes our requests" in r.getMessage() for r in caplog.records)
