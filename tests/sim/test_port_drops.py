"""Lost ports: an end cut for a while (a gateway restarting, an adapter pulled), at random."""

from __future__ import annotations

import asyncio
import contextlib
import errno
import os
import pathlib
import random
import signal
import socket
import subprocess
import sys
from collections.abc import Callable

import pytest
import serial_asyncio

from pkwbus.sim import ModelConfig, SimFaults, SimTiming, Simulator
from pkwbus.sim.serving.ends import drop_at_random
from tests.sim.test_ends import READ, Telegrams

QUIET = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0)


def simulator() -> Simulator:
    return Simulator("fc", [1], timing=SimTiming(response_delay=0.0), seed=1, model=QUIET)


async def answered(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> bool:
    writer.write(READ)
    return (await Telegrams(reader).next()).adr == 1


async def cut(reader: asyncio.StreamReader) -> bool:
    """Whether the connection ends (the peer closed or reset it) before any data."""
    try:
        return await asyncio.wait_for(reader.read(256), 5.0) == b""
    except ConnectionError:
        return True


async def test_a_tcp_end_cuts_its_connections_for_the_outage_then_serves_again() -> None:
    end = await simulator().serve_tcp("127.0.0.1", 0)
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", end.port)
        assert await answered(reader, writer)
        lost = asyncio.create_task(end.interrupt(60.0))
        assert await cut(reader)  # the connection in use is cut
        writer.close()
        # A connection made while the port is lost is cut at once, unanswered.
        reader, writer = await asyncio.open_connection("127.0.0.1", end.port)
        writer.write(READ)
        assert await cut(reader)
        writer.close()
        assert not lost.done()
        lost.cancel()  # the port is back at once
        await asyncio.gather(lost, return_exceptions=True)
        reader, writer = await asyncio.open_connection("127.0.0.1", end.port)
        assert await answered(reader, writer)
        writer.close()
    finally:
        await end.close()


async def test_interrupt_returns_when_the_tcp_port_is_back() -> None:
    end = await simulator().serve_tcp("127.0.0.1", 0)
    try:
        await end.interrupt(0.05)
        reader, writer = await asyncio.open_connection("127.0.0.1", end.port)
        assert await answered(reader, writer)
        writer.close()
    finally:
        await end.close()


async def test_a_pty_end_removes_its_pty_for_the_outage_and_makes_a_new_one(
    tmp_path: pathlib.Path,
) -> None:
    link = str(tmp_path / "ttySIM")
    end = await simulator().serve_pty(link)
    old = os.open(link, os.O_RDWR | os.O_NOCTTY)
    try:
        lost = asyncio.create_task(end.interrupt(0.2))
        # Timers run in order: this look comes before the outage's end.
        await wait_until(lambda: not os.path.lexists(link))
        assert not lost.done()
        with pytest.raises(OSError) as failed:  # the client's pty is gone
            os.write(old, READ)
        assert failed.value.errno == errno.EIO
        await lost
        assert os.path.islink(link) and os.readlink(link) == end.device
        reader, writer = await serial_asyncio.open_serial_connection(url=link, baudrate=19200)
        assert await answered(reader, writer)
        writer.close()
    finally:
        os.close(old)
        await end.close()
    assert not os.path.lexists(link)


async def test_a_pty_lost_is_back_at_once_when_the_loss_is_cancelled(
    tmp_path: pathlib.Path,
) -> None:
    link = str(tmp_path / "ttySIM")
    end = await simulator().serve_pty(link)
    try:
        lost = asyncio.create_task(end.interrupt(3600.0))
        await wait_until(lambda: not os.path.lexists(link))
        lost.cancel()
        await asyncio.gather(lost, return_exceptions=True)
        assert os.path.islink(link) and os.readlink(link) == end.device
        reader, writer = await serial_asyncio.open_serial_connection(url=link, baudrate=19200)
        assert await answered(reader, writer)
        writer.close()
    finally:
        await end.close()


async def test_a_late_answer_of_a_lost_pty_never_reaches_whatever_has_its_number_now(
    tmp_path: pathlib.Path,
) -> None:
    faults = SimFaults(late=1.0, late_seconds=0.3)
    sim = Simulator("fc", [1], timing=SimTiming(0.0), seed=1, faults=faults, model=QUIET)
    end = await sim.serve_pty(str(tmp_path / "ttySIM"))
    controller = end._fds[0] if end._fds else -1
    client = os.open(end.path, os.O_RDWR | os.O_NOCTTY)
    try:
        os.write(client, READ)
        await wait_until(lambda: sim.stats.line["responses"] == 1)  # the answer is due later
        await end.close()
        # The lowest free descriptors go to the next file opened: now a socket's.
        mine, other = socket.socketpair()
        try:
            assert mine.fileno() == controller
            other.setblocking(False)
            await asyncio.sleep(0.6)  # past the late answer's time
            with pytest.raises(BlockingIOError):
                other.recv(64)
        finally:
            mine.close()
            other.close()
    finally:
        os.close(client)


async def wait_until(check: Callable[[], bool]) -> None:
    async with asyncio.timeout(10):
        while not check():
            await asyncio.sleep(0.005)


class Counted:
    """An end that counts its losses."""

    def __init__(self) -> None:
        self.outages: list[float] = []

    async def interrupt(self, outage: float) -> None:
        self.outages.append(outage)


async def test_ports_are_lost_at_random_at_the_rate_asked_and_said() -> None:
    end, said = Counted(), list[str]()
    per_second = 200.0
    task = asyncio.create_task(
        drop_at_random(end, per_second * 3600, 0.5, random.Random(7), said.append)
    )
    loop = asyncio.get_running_loop()
    began = loop.time()
    await wait_until(lambda: len(end.outages) >= 100)
    took = loop.time() - began
    task.cancel()
    await asyncio.gather(task, return_exceptions=True)
    assert set(end.outages) == {0.5} and said[0] == "port lost for 0.5 s"
    assert len(said) == len(end.outages)
    # 100 exponential waits of mean 5 ms: at least 0.5 s minus a generous spread (a busy
    # machine only makes the run longer).
    assert took > 100 / per_second * 0.6


async def test_a_port_never_lost_when_the_rate_is_0() -> None:
    end = Counted()
    task = asyncio.create_task(drop_at_random(end, 0.0, 0.5, random.Random(7)))
    with pytest.raises(TimeoutError):
        await asyncio.wait_for(asyncio.shield(task), 0.2)
    task.cancel()
    await asyncio.gather(task, return_exceptions=True)
    assert end.outages == []


def simulate(*options: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pkwbus.sim", "--drives", "1", *options],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def said(proc: subprocess.Popen[str], start: str) -> str:
    assert proc.stdout is not None
    while line := proc.stdout.readline():
        if line.startswith(start):
            return line.strip()
    raise AssertionError(f"the simulator ended: {proc.stderr.read() if proc.stderr else ''}")


def test_the_command_line_loses_its_tcp_port_at_random_and_stops_cleanly() -> None:
    proc = simulate(
        "--listen", "tcp://127.0.0.1:0", "--drop-port-per-hour", "3600", "--port-outage", "50ms"
    )
    try:
        url = said(proc, "simulating").split(" on ")[-1]
        host, port = url.removeprefix("socket://").rsplit(":", 1)
        with socket.create_connection((host, int(port)), timeout=30) as conn:
            assert said(proc, "port lost") == "port lost for 0.05 s"
            conn.settimeout(30)
            with contextlib.suppress(ConnectionResetError):
                assert conn.recv(64) == b""  # cut
    finally:
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=30)
    assert code == 0


def test_a_pty_that_cannot_be_made_again_ends_the_simulator_with_exit_2(
    tmp_path: pathlib.Path,
) -> None:
    link = tmp_path / "ttySIM"
    proc = simulate("--pty", str(link), "--drop-port-per-hour", "3600", "--port-outage", "3s")
    try:
        said(proc, "simulating")
        said(proc, "port lost")
        # Someone puts a file at the path while the port is lost: never replaced.
        other = tmp_path / "other"
        other.write_text("not a pty")
        os.replace(other, link)
        code = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.stderr is not None
    err = proc.stderr.read()
    assert code == 2, err
    assert err.startswith("pkwbus simulate: error:") and "not a symlink" in err
    assert err.count("\n") == 1
    assert link.read_text() == "not a pty"
