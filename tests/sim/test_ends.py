"""The ends: TCP (raw client, pyserial socket:// URL) and the pty (pyserial-asyncio)."""

from __future__ import annotations

import asyncio
import os
import pathlib
import time

import pytest
import serial
import serial_asyncio

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import FC, USS
from pkwbus.protocol.serial.telegram import Deframer, Telegram, fc_lengths
from pkwbus.sim import ModelConfig, SimFaults, SimTiming, Simulator
from pkwbus.sim.serving.ends import PathInUseError
from tests.sim.conftest import request_telegram

QUIET = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0)
READ = request_telegram(1, pkw.read(FC, 1613), FC)


class Telegrams:
    """Telegrams from a stream, in order, kept across reads."""

    def __init__(self, reader: asyncio.StreamReader) -> None:
        self.reader = reader
        self.deframer = Deframer(fc_lengths())
        self.pending: list[Telegram] = []

    async def next(self, timeout: float = 2.0) -> Telegram:
        async with asyncio.timeout(timeout):
            while not self.pending:
                events = self.deframer.feed(await self.reader.read(256))
                self.pending += [e for e in events if isinstance(e, Telegram)]
        return self.pending.pop(0)


async def read_telegram(reader: asyncio.StreamReader) -> Telegram:
    return await Telegrams(reader).next()


async def exchange_time(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> float:
    start = time.perf_counter()
    writer.write(READ)
    await read_telegram(reader)
    return time.perf_counter() - start


async def test_tcp_raw_client_and_many_drives() -> None:
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.0), seed=1, model=QUIET)
    end = await sim.serve_tcp("127.0.0.1", 0)
    try:
        assert end.url == f"socket://127.0.0.1:{end.port}"
        reader, writer = await asyncio.open_connection("127.0.0.1", end.port)
        writer.write(b"\xff\x00garbage" + READ + request_telegram(2, pkw.read(FC, 414), FC))
        telegrams = Telegrams(reader)
        first, second = await telegrams.next(), await telegrams.next()
        assert (first.adr, second.adr) == (1, 2)
        resp = pkw.decode_response(second.data[:8], FC, FC.default_ind_layout)
        assert isinstance(resp, pkw.ValueResponse) and resp.raw == sim.drives[2].value(414)
        assert sim.stats.as_dict()["bad_requests"] == 1  # the garbage, reported once
        writer.close()
    finally:
        await end.close()


async def test_response_delay_and_wire_timing_are_measured() -> None:
    timing = SimTiming(response_delay=0.02, baudrate=9600, wire_timing=True)
    sim = Simulator("fc", [1], timing=timing, seed=1, model=QUIET)
    end = await sim.serve_tcp("127.0.0.1", 0)
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", end.port)
        times = sorted([await exchange_time(reader, writer) for _ in range(5)])
        expected = 0.02 + 2 * 16 * 11 / 9600  # request + delay + answer: 56.7 ms
        assert expected <= times[2] < expected + 0.03
        writer.close()
    finally:
        await end.close()


async def test_late_answer_arrives_after_the_masters_timeout() -> None:
    faults = SimFaults(late=1.0, late_seconds=0.2)
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), faults=faults, seed=1)
    end = await sim.serve_tcp("127.0.0.1", 0)
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", end.port)
        start = time.perf_counter()
        writer.write(READ)
        await read_telegram(reader)
        assert time.perf_counter() - start >= 0.2
        writer.close()
    finally:
        await end.close()


async def test_pyserial_asyncio_over_the_pty(tmp_path: pathlib.Path) -> None:
    sim = Simulator("uss", [3], timing=SimTiming(response_delay=0.001), seed=1, model=QUIET)
    link = str(tmp_path / "ttySIM0")
    end = await sim.serve_pty(link)
    try:
        assert end.path == link and pathlib.Path(link).is_symlink()
        reader, writer = await serial_asyncio.open_serial_connection(url=link, baudrate=19200)
        req = pkw.read(USS, 1082)
        writer.write(request_telegram(3, req, USS))
        answer = await read_telegram(reader)
        resp = pkw.decode_response(answer.data[:8], USS, USS.default_ind_layout)
        assert pkw.matches(req, resp, USS) and answer.adr == 3
        writer.close()
    finally:
        await end.close()
    assert not pathlib.Path(link).exists()


async def test_pyserial_socket_url_reaches_the_tcp_end() -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.001), seed=1, model=QUIET)
    end = await sim.serve_tcp("127.0.0.1", 0)

    def blocking_exchange() -> bytes:
        with serial.serial_for_url(end.url, timeout=2) as port:
            port.write(READ)
            return bytes(port.read(16))

    try:
        answer = await asyncio.to_thread(blocking_exchange)
        assert len(answer) == 16 and answer[2] == 1
        reader, writer = await serial_asyncio.open_serial_connection(url=end.url)
        writer.write(READ)
        assert (await read_telegram(reader)).adr == 1
        writer.close()
    finally:
        await end.close()
    assert sim.stats.as_dict()["responses"] == 2


async def test_a_link_in_use_or_not_ours_is_never_replaced(tmp_path: pathlib.Path) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.001), seed=1, model=QUIET)
    link = tmp_path / "ttySIM0"
    first = await sim.serve_pty(str(link))
    other_file = tmp_path / "file"
    other_file.write_text("")
    elsewhere = tmp_path / "ttyUSB"
    elsewhere.symlink_to("/dev/null")
    try:
        for path in (link, other_file, elsewhere):
            before = os.readlink(path) if path.is_symlink() else None
            with pytest.raises(PathInUseError, match=str(path)):
                await sim.serve_pty(str(path))
            assert (os.readlink(path) if path.is_symlink() else None) == before
    finally:
        await first.close()
    assert not link.exists() and other_file.exists() and elsewhere.is_symlink()


async def test_a_link_to_a_pty_no_simulator_holds_is_stale(tmp_path: pathlib.Path) -> None:
    """The number of a dead simulator's pty may be in use by another terminal meanwhile."""
    controller, follower = os.openpty()
    link = tmp_path / "ttySIM0"
    link.symlink_to(os.ttyname(follower))
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.001), seed=1, model=QUIET)
    try:
        end = await sim.serve_pty(str(link))
        assert os.readlink(link) == end.device != os.ttyname(follower)
        await end.close()
    finally:
        os.close(controller)
        os.close(follower)
    assert not os.path.lexists(link)
