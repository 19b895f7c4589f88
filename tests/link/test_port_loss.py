"""A port is lost only when it is lost.

On a tty a read may find nothing (its input was discarded after the loop
found it readable): that is no loss. A pty whose other end closes, a hung-up
tty (what an unplugged USB adapter leaves), a read failing with EIO, a tty
that stays readable and gives nothing, and a TCP gateway that closes are.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import fcntl
import logging
import os
import select
import socket
import sys
import tty
from collections.abc import AsyncIterator, Iterator

import pytest

from pkwbus.link import Link, LinkState, PortSettings
from pkwbus.link.transport import EMPTY_READS_LOST_AFTER, EmptyReads, SerialTransport

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux ptys")

# Linux's request to hang a terminal up, as vhangup(2) does; the kernel does the
# same to the tty of a USB serial adapter that is unplugged.
TIOCVHANGUP = 0x5437


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    """A pty's controller (the far end, kept open) and the path of its follower."""
    controller, follower = os.openpty()
    tty.setraw(follower)
    try:
        yield controller, os.ttyname(follower)
    finally:
        for fd in (controller, follower):
            with contextlib.suppress(OSError):  # closed by the test
                os.close(fd)


class Watched:
    """A link whose receiver and loss listener record what they get."""

    def __init__(self, url: str) -> None:
        self.got = bytearray()
        self.lost: list[str] = []
        self.lost_event = asyncio.Event()
        self.arrived = asyncio.Event()
        self.link = Link(
            PortSettings(url, baudrate=19200), receiver=self._receive, on_lost=self._lose
        )

    def _receive(self, data: bytes) -> None:
        self.got += data
        self.arrived.set()

    def _lose(self, reason: str) -> None:
        self.lost.append(reason)
        self.lost_event.set()

    @property
    def transport(self) -> SerialTransport:
        transport = self.link._transport
        assert transport is not None
        return transport

    async def wait_lost(self) -> str:
        await asyncio.wait_for(self.lost_event.wait(), 10.0)
        return self.lost[0]

    async def receives(self, controller: int, data: bytes) -> None:
        """``data`` written at the far end reaches the receiver (after any input before it)."""
        self.arrived.clear()
        os.write(controller, data)
        while not self.got.endswith(data):
            await asyncio.wait_for(self.arrived.wait(), 10.0)
            self.arrived.clear()


def wait_readable(fd: int) -> None:
    """Block until ``fd`` holds input (the loop's next poll finds it readable)."""
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    assert poller.poll(10_000), "the pty never became readable"


async def turns(n: int = 3) -> None:
    """Let the loop run ``n`` times round: the callbacks queued meanwhile all run."""
    for _ in range(n):
        await asyncio.sleep(0)


@contextlib.asynccontextmanager
async def opened(path: str) -> AsyncIterator[Watched]:
    """The link of ``path`` opened and watched for losses; closed at the end."""
    watched = Watched(path)
    await watched.link.open()
    try:
        yield watched
    finally:
        await watched.link.close()


async def test_input_discarded_between_the_readiness_and_the_read_is_no_loss(
    pty: tuple[int, str],
) -> None:
    controller, path = pty
    async with opened(path) as watched:
        await turns()
        transport = watched.transport
        reads: list[bytes] = []
        real_read = transport._read

        def recorded(size: int) -> bytes:
            reads.append(real_read(size))
            return reads[-1]

        transport._read = recorded  # type: ignore[method-assign]
        os.write(controller, b"\x55" * 8)  # stray input: a late answer, noise
        wait_readable(watched.link._fd)
        # The discard runs first in the loop's next round, the read it found due after it:
        # callbacks queued before a round run before the readers its poll found ready.
        loop = asyncio.get_running_loop()
        loop.call_soon(lambda: watched.link.write_now(b"\x02", discard=True))
        await turns()
        assert not watched.lost
        assert watched.link.state is LinkState.OPEN
        assert reads[0] == b"\x55" * 8 and reads[-1] == b"", reads  # the due read found nothing
        assert not watched.got  # the stray input was dropped, not handed over
        await watched.receives(controller, b"\x68\x03")  # and the port is still read
    assert not watched.lost


async def test_the_far_end_of_a_pty_closing_is_a_loss(pty: tuple[int, str]) -> None:
    controller, path = pty
    async with opened(path) as watched:
        await watched.receives(controller, b"\x01")
        os.close(controller)
        assert "hung up" in await watched.wait_lost()
        assert watched.link.state is LinkState.FAILED
    assert len(watched.lost) == 1


async def test_a_hung_up_tty_is_a_loss(pty: tuple[int, str]) -> None:
    """What the kernel leaves of an unplugged USB adapter: reads give 0 bytes, polls HUP."""
    _controller, path = pty
    async with opened(path) as watched:
        try:
            fcntl.ioctl(watched.link._fd, TIOCVHANGUP)
        except OSError as exc:
            pytest.skip(f"cannot hang a tty up here: {os.strerror(exc.errno or 0)}")
        assert "hung up" in await watched.wait_lost()


async def test_a_read_failing_with_eio_is_a_loss(pty: tuple[int, str]) -> None:
    controller, path = pty
    async with opened(path) as watched:
        await turns()

        def unplugged(size: int) -> bytes:
            raise OSError(errno.EIO, os.strerror(errno.EIO))

        watched.transport._read = unplugged  # type: ignore[method-assign]
        os.write(controller, b"\x01")
        assert await watched.wait_lost() == f"lost {path}: {os.strerror(errno.EIO)}"


async def test_a_port_lost_at_a_write_is_told_once_without_a_traceback(
    pty: tuple[int, str], caplog: pytest.LogCaptureFixture
) -> None:
    controller, path = pty
    async with opened(path) as watched:
        await turns()
        os.close(controller)
        with caplog.at_level(logging.DEBUG):
            watched.link.write_now(b"\x02\x04", discard=False)  # EIO: the tty is hung up
            await watched.wait_lost()
            await turns()
    assert len(watched.lost) == 1
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR or r.exc_info]


def test_empty_reads_are_a_loss_once_they_last_the_time_set() -> None:
    reads = EmptyReads(lost_after=0.5)
    assert not reads.readable_but_empty(10.0)
    assert not reads.readable_but_empty(10.49)
    reads.reset()  # input came
    assert not reads.readable_but_empty(11.0)
    assert not reads.readable_but_empty(11.4)
    assert reads.readable_but_empty(11.5)
    assert EMPTY_READS_LOST_AFTER < 1.0  # an unplugged adapter is noticed within a second


async def test_a_tty_readable_without_input_for_the_time_set_is_a_loss(
    pty: tuple[int, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """An adapter gone without a hang-up: every read finds nothing, every poll says readable."""
    _controller, path = pty
    async with opened(path) as watched:
        await turns()
        transport = watched.transport
        now = 100.0
        transport.clock = lambda: now
        readable = select.POLLIN
        monkeypatch.setattr(transport, "_poll", lambda: readable)
        transport._read_ready()  # the run begins
        now += EMPTY_READS_LOST_AFTER / 2
        transport._read_ready()
        readable = 0  # the tty had no input after all: the run is over
        transport._read_ready()
        readable = select.POLLIN
        now += EMPTY_READS_LOST_AFTER / 2
        transport._read_ready()  # a new run begins
        now += EMPTY_READS_LOST_AFTER * 0.99
        transport._read_ready()
        assert not transport.is_closing()
        now += EMPTY_READS_LOST_AFTER * 0.01
        transport._read_ready()
        assert transport.is_closing()
        assert "readable but gave nothing" in await watched.wait_lost()


async def test_data_between_empty_reads_starts_the_run_again(
    pty: tuple[int, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    controller, path = pty
    async with opened(path) as watched:
        await turns()
        transport = watched.transport
        now = 100.0
        transport.clock = lambda: now
        monkeypatch.setattr(transport, "_poll", lambda: select.POLLIN)
        transport._read_ready()
        now += EMPTY_READS_LOST_AFTER * 0.9
        await watched.receives(controller, b"\x01\x02")
        transport._read_ready()
        now += EMPTY_READS_LOST_AFTER * 0.9
        transport._read_ready()
        assert not transport.is_closing()
    assert not watched.lost


async def test_the_end_of_a_tcp_stream_is_a_loss() -> None:
    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        watched = Watched(f"socket://127.0.0.1:{port}")
        await watched.link.open()
        try:
            far, _ = server.accept()
            # Input to discard, then the end of the stream: the discard leaves the end
            # to the reader.
            far.sendall(b"\x02\x03")
            far.close()
            wait_readable(watched.link._fd)
            watched.link._discard_input()
            assert "closed at its other end" in await watched.wait_lost()
            assert not watched.got
        finally:
            await watched.link.close()


async def test_a_transport_closed_earlier_does_not_take_the_reopened_port_down(
    pty: tuple[int, str],
) -> None:
    """The end of the transport a close left writing comes after the port was opened again."""
    controller, path = pty
    os.set_blocking(controller, False)
    watched = Watched(path)
    await watched.link.open()
    await turns()
    old = watched.transport
    watched.link.write_now(b"\x00" * 300_000, discard=False)  # more than the pty takes
    assert old.get_write_buffer_size() > 0
    await watched.link.close()  # the old transport ends once its output is written
    await watched.link.open()
    try:
        while old._loop is not None:  # read the output until the old transport is over
            with contextlib.suppress(BlockingIOError):
                os.read(controller, 65536)
            await asyncio.sleep(0.001)
        await turns()
        assert not watched.lost
        assert watched.link.state is LinkState.OPEN
        await watched.receives(controller, b"\x07")
    finally:
        await watched.link.close()
