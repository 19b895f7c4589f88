"""A fenced link (hot standby) never opens nor writes once its lease may have passed to
another instance: the fence is asked at the opening and before every write, on
``FENCE_CLOCK`` (CLOCK_BOOTTIME on Linux), and a refused write gives the port up with the reason."""

from __future__ import annotations

import asyncio
import math
import os
import select
import socket
import tty
from collections.abc import AsyncIterator, Iterator

import pytest

from pkwbus.link import ALWAYS_OPEN, Link, LinkState, PortError, PortSettings
from pkwbus.link.fence import FENCE_CLOCK, LineFence, fence_closed, fenced_reason
from pkwbus.master.wires.profibus.port import FdlPort
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.protocol.buses import Bus


class FakeFence:
    """A fence the test moves: open until ``until`` on FENCE_CLOCK."""

    def __init__(self, until: float = math.inf) -> None:
        self.until = until
        self.asked = 0

    def open_until(self) -> float:
        self.asked += 1
        return self.until

    def close(self) -> None:
        self.until = FENCE_CLOCK() - 0.001


def readable(fd: int, timeout: float) -> bool:
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    return bool(poller.poll(int(timeout * 1000)))


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    controller, follower = os.openpty()
    tty.setraw(follower)
    try:
        yield controller, os.ttyname(follower)
    finally:
        os.close(controller)
        os.close(follower)


def test_always_open_never_closes() -> None:
    assert ALWAYS_OPEN.open_until() == math.inf
    assert not fence_closed(ALWAYS_OPEN)


def test_a_line_fence_names_its_line_and_asks_the_engines_fence() -> None:
    inner = FakeFence(FENCE_CLOCK() + 100)
    fence = LineFence("hall-a", inner)
    assert fence.open_until() == inner.until
    assert "line hall-a is no longer mastered here" in fenced_reason(fence)
    inner.close()
    assert fence_closed(fence)


async def test_a_closed_fence_refuses_the_opening(pty: tuple[int, str]) -> None:
    _, path = pty
    fence = FakeFence(0.0)  # not held: 0.0, as the engine's fence of a line not held
    link = Link(PortSettings(path, baudrate=19200), fence=LineFence("l1", fence))
    with pytest.raises(PortError, match="line l1 is no longer mastered here"):
        await link.open()
    assert link.state is LinkState.FAILED and not link.is_open
    assert link.reconnect.last_error is not None
    assert "line l1 is no longer mastered here" in link.reconnect.last_error
    fence.until = FENCE_CLOCK() + 60  # won: the port opens
    await link.open()
    assert link.is_open
    await link.close()


async def test_writes_go_out_while_open_and_none_once_the_fence_closed(
    pty: tuple[int, str],
) -> None:
    controller, path = pty
    fence = FakeFence(FENCE_CLOCK() + 60)
    lost: list[str] = []
    link = Link(PortSettings(path, baudrate=19200), fence=LineFence("l1", fence),
                on_lost=lost.append)  # fmt: skip
    await link.open()
    try:
        asked = fence.asked
        link.write_now(b"\x02\x04", discard=False)
        assert fence.asked > asked  # asked at the write, not only at the opening
        assert readable(controller, 5.0)
        assert os.read(controller, 64) == b"\x02\x04"
        fence.close()  # e.g. a process resumed after SIGSTOP: the lease is stale
        with pytest.raises(PortError, match="line l1 is no longer mastered here"):
            link.write_now(b"\x02\x05", discard=False)
        with pytest.raises(PortError):
            await link.send(b"\x02\x06")
        assert not link.is_open and link.state is LinkState.FAILED  # given up
        assert readable(controller, 0.3) is False  # not a byte went out
        assert "line l1 is no longer mastered here" in (link.reconnect.last_error or "")
        # Reopened at back-off: refused while the fence stays closed.
        assert await link.reopen() is False
        assert not link.is_open
    finally:
        await link.close()


@pytest.fixture
async def gateway() -> AsyncIterator[tuple[str, list[bytes], asyncio.Event]]:
    """A TCP 'gateway' on loopback that records what reaches it."""
    got: list[bytes] = []
    arrived = asyncio.Event()
    closed = asyncio.Event()

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        while data := await reader.read(64):
            got.append(data)
            arrived.set()
        closed.set()
        writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0, family=socket.AF_INET)
    port = server.sockets[0].getsockname()[1]
    try:
        yield f"socket://127.0.0.1:{port}", got, closed
    finally:
        server.close()
        await server.wait_closed()


async def test_a_refused_write_closes_the_gateway_connection(
    gateway: tuple[str, list[bytes], asyncio.Event],
) -> None:
    """Over ``socket://`` the refusal closes the connection: a gateway that admits one
    connection is free for the new master."""
    url, got, closed = gateway
    fence = FakeFence(FENCE_CLOCK() + 60)
    link = Link(PortSettings(url, baudrate=19200), fence=fence)
    await link.open()
    link.write_now(b"\x01", discard=False)
    loop = asyncio.get_running_loop()
    end = loop.time() + 10
    while not got and loop.time() < end:
        await asyncio.sleep(0.01)
    assert got == [b"\x01"]
    fence.close()
    with pytest.raises(PortError, match="its line is no longer mastered here"):
        link.write_now(b"\x02", discard=False)
    await asyncio.wait_for(closed.wait(), 10.0)
    assert b"".join(got) == b"\x01"
    await link.close()


async def test_a_link_without_a_fence_is_always_open(pty: tuple[int, str]) -> None:
    controller, path = pty
    link = Link(PortSettings(path, baudrate=19200))
    assert link.fence is ALWAYS_OPEN
    await link.open()
    link.write_now(b"\x07", discard=False)
    assert readable(controller, 5.0)
    await link.close()


def test_the_ports_of_both_buses_hand_their_fence_to_their_link() -> None:
    fence = FakeFence(0.0)
    settings = PortSettings("socket://127.0.0.1:1", baudrate=19200)
    assert TelegramPort(settings, Bus.FC, fence=fence).link.fence is fence
    assert FdlPort(settings, 2, fence=fence).link.fence is fence
    assert TelegramPort(settings, Bus.FC).link.fence is ALWAYS_OPEN


def test_the_fence_clock_counts_a_suspend_where_the_system_can(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """CLOCK_BOOTTIME where it exists (Linux: it runs on through a system suspend, which
    time.monotonic() does not count), else time.monotonic."""
    import sys
    import time

    from pkwbus.link.fence import pick_clock

    if sys.platform.startswith("linux"):
        assert hasattr(time, "CLOCK_BOOTTIME")
    asked: list[int] = []

    def clock_gettime(clock_id: int) -> float:
        asked.append(clock_id)
        return 1234.5

    monkeypatch.setattr(time, "CLOCK_BOOTTIME", 7, raising=False)
    monkeypatch.setattr(time, "clock_gettime", clock_gettime)
    picked = pick_clock()
    assert picked() == 1234.5 and asked == [7]
    monkeypatch.delattr(time, "CLOCK_BOOTTIME")
    assert pick_clock() is time.monotonic


def test_the_picked_clock_is_boottime_here() -> None:
    import sys
    import time

    if not sys.platform.startswith("linux"):
        pytest.skip("CLOCK_BOOTTIME is Linux's")
    before = time.clock_gettime(time.CLOCK_BOOTTIME)
    now = FENCE_CLOCK()
    after = time.clock_gettime(time.CLOCK_BOOTTIME)
    assert before <= now <= after


def test_a_fence_is_closed_on_the_clock_given() -> None:
    fence = FakeFence(100.0)
    assert not fence_closed(fence, lambda: 99.999)
    assert fence_closed(fence, lambda: 100.0)
    assert fence_closed(fence, lambda: 1e9)
    assert not fence_closed(ALWAYS_OPEN, lambda: 1e300)
