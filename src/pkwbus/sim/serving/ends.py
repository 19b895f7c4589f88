"""The simulator's ends: a TCP server (raw telegram bytes) and a pseudo-terminal.

Each connection is answered by a :class:`~pkwbus.sim.serving.session.Session`, with the
timing of an RS-485 line.

An end can lose its port for a while (:meth:`TcpEnd.interrupt`,
:meth:`PtyEnd.interrupt`), at random with :func:`drop_at_random`: a gateway
that restarts, a USB adapter pulled and plugged in again.

Raises: :class:`PathInUseError` when a pty's link path is taken;
:class:`OSError` when a pty or a TCP port cannot be had.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import fcntl
import os
import random
import struct
import tty
from collections.abc import Callable
from typing import Protocol

from pkwbus.errors import PkwbusError
from pkwbus.sim.serving.session import Answerer, Session

__all__ = [
    "Answerer", "Interruptible", "PathInUseError", "PtyEnd", "Session", "TcpEnd",
    "check_link_free", "drop_at_random", "serve_pty", "serve_tcp",
]  # fmt: skip


class TcpEnd:
    """Raw telegram bytes over TCP, like a serial-over-TCP gateway (pyserial ``socket://``)."""

    def __init__(self, sim: Answerer) -> None:
        self.sim = sim
        self.host = ""
        self.port = 0
        self._server: asyncio.Server | None = None
        self._clients: dict[asyncio.Task[None], asyncio.StreamWriter] = {}
        self._lost_until = 0.0  # loop time until which the port is lost (interrupt)
        self.connections = 0  # clients accepted: a master that reopened its port counts twice

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"socket://{host}:{self.port}"

    async def start(self, host: str, port: int) -> None:
        self._server = await asyncio.start_server(self._client, host, port)
        self.host, self.port = self._server.sockets[0].getsockname()[:2]

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if asyncio.get_running_loop().time() < self._lost_until:
            writer.transport.abort()  # the port is lost: cut at once
            return
        task = asyncio.current_task()
        assert task is not None
        self.connections += 1
        self._clients[task] = writer
        session = Session(self.sim, writer.write)
        try:
            while data := await reader.read(4096):
                session.feed(data)
        except ConnectionError:
            pass
        finally:
            self._clients.pop(task, None)
            await session.close()
            writer.close()

    async def interrupt(self, outage: float) -> None:
        """Lose the port for ``outage`` seconds, as a gateway that restarts: every
        connection is cut, and one made meanwhile is cut at once. Returns when the
        port is back; cancelled, the port is back at once. The listening socket
        stays ours, so the port number cannot go to another program meanwhile."""
        loop = asyncio.get_running_loop()
        self._lost_until = loop.time() + outage
        try:
            await self._cut_clients()
            await asyncio.sleep(max(0.0, self._lost_until - loop.time()))
        finally:
            self._lost_until = 0.0

    async def _cut_clients(self) -> None:
        clients = dict(self._clients)
        for writer in clients.values():
            writer.transport.abort()  # the handler sees the end of the stream and cleans up
        await asyncio.gather(*clients, return_exceptions=True)

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
        await self._cut_clients()
        if self._server is not None:
            await self._server.wait_closed()


class PathInUseError(PkwbusError):
    """The pty's link path is taken: by a live simulator, or by something not ours to replace."""


class PtyEnd:
    """A pseudo-terminal: the follower side is reachable at ``path`` (a symlink).

    While it runs, the end holds a lock on its follower (an open-file-description
    lock, which no serial client takes or notices). A path that exists is
    refused (:class:`PathInUseError`) unless it is a stale link left by a
    simulator that died without removing it: a symlink to a ``/dev/pts/N``
    that no longer exists, or whose pty no simulator holds locked (the number
    may have been reused by another terminal).
    """

    def __init__(self, sim: Answerer, link: str) -> None:
        self.sim = sim
        self.path = link
        self.device = ""
        self._fds: tuple[int, int] | None = None
        self._session: Session | None = None

    async def start(self) -> None:
        check_link_free(self.path)
        controller, follower = os.openpty()
        try:
            if _OFD_SETLK is not None:
                _lock(follower)
            tty.setraw(follower)
            os.set_blocking(controller, False)
            self.device = os.ttyname(follower)
            _publish(self.device, self.path)
        except BaseException:
            os.close(controller)
            os.close(follower)
            raise
        self._fds = (controller, follower)  # we keep the follower open: no hang-up between users
        self._session = Session(self.sim, lambda data: _write_all(controller, data))
        asyncio.get_running_loop().add_reader(controller, self._readable)

    def _readable(self) -> None:
        assert self._fds is not None and self._session is not None
        try:
            data = os.read(self._fds[0], 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # EIO: nobody holds the follower side; wait for the next user
            return
        self._session.feed(data)

    async def interrupt(self, outage: float) -> None:
        """Lose the port for ``outage`` seconds, as a USB adapter pulled and plugged in
        again: the pty and its link go (a client's reads and writes fail), then a new
        pty is linked at the same path. Returns when it is there (cancelled: at
        once); raises as :meth:`start` when it cannot be made again."""
        await self.close()
        try:
            await asyncio.sleep(outage)
        finally:
            await self.start()

    async def close(self) -> None:
        if self._fds is None:
            return
        asyncio.get_running_loop().remove_reader(self._fds[0])
        if self._session is not None:
            await self._session.close()
        for fd in self._fds:
            os.close(fd)
        self._fds = None
        if os.path.islink(self.path) and os.readlink(self.path) == self.device:
            os.unlink(self.path)


PTY_DIR = "/dev/pts"
# struct flock begins with ``short l_type``; the rest zero: whole file, l_pid 0 (required
# for open-file-description locks). Room for the largest struct flock of any platform.
_FLOCK_SIZE = 64


# Open-file-description locks are Linux's; elsewhere a pty that exists counts as held.
_OFD_SETLK: int | None = getattr(fcntl, "F_OFD_SETLK", None)


def _lock(fd: int) -> None:
    """Write-lock the whole file behind ``fd`` (OSError EAGAIN/EACCES when another holds it)."""
    if _OFD_SETLK is None:
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))
    flock = struct.pack("h", fcntl.F_WRLCK).ljust(_FLOCK_SIZE, b"\0")
    fcntl.fcntl(fd, _OFD_SETLK, flock)


def check_link_free(path: str, own: str = "") -> None:
    """Refuse (PathInUseError) a ``path`` in use; a stale simulator link passes, to be replaced.

    ``own`` is the caller's new pty, which may have the stale link's number.
    """
    if not os.path.lexists(path):
        return
    if not os.path.islink(path):
        raise PathInUseError(f"{path} exists and is not a symlink; nothing replaced")
    target = os.readlink(path)
    if target == own:
        return
    if os.path.dirname(target) != PTY_DIR:
        raise PathInUseError(f"{path} is a link to {target}, not to a pty; nothing replaced")
    if _held(target):
        raise PathInUseError(
            f"{path} is in use: another simulator serves {target} there; nothing replaced"
        )


def _held(device: str) -> bool:
    """Whether a running simulator holds the pty ``device`` (its follower locked)."""
    try:
        fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError:  # gone with its simulator, or another user's terminal: no simulator of ours
        return False
    try:
        _lock(fd)
    except OSError:
        return True
    finally:
        os.close(fd)  # releases our probe's lock
    return False


def _publish(device: str, path: str) -> None:
    """Make ``path`` a symlink to ``device``: created anew, or a stale link replaced in one step."""
    try:
        os.symlink(device, path)
        return
    except FileExistsError:
        pass
    check_link_free(path, own=device)  # still stale (checked again just before the swap)
    temporary = f"{path}.{os.getpid()}.new"
    with contextlib.suppress(FileNotFoundError):
        os.unlink(temporary)
    os.symlink(device, temporary)
    try:
        os.replace(temporary, path)
    except OSError:
        os.unlink(temporary)
        raise


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


class Interruptible(Protocol):
    """An end that can lose its port for a while."""

    async def interrupt(self, outage: float) -> None: ...


async def drop_at_random(
    end: Interruptible,
    per_hour: float,
    outage: float,
    rng: random.Random,
    said: Callable[[str], None] | None = None,
) -> None:
    """Lose ``end``'s port at random, on average ``per_hour`` times an hour of port
    time (a Poisson process), each time for ``outage`` seconds; until cancelled.
    ``said`` is told of each loss. Raises as the end's ``interrupt``."""
    if per_hour <= 0:
        await asyncio.Event().wait()  # never
    while True:
        await asyncio.sleep(rng.expovariate(per_hour / 3600))
        if said is not None:
            said(f"port lost for {outage:g} s")
        await end.interrupt(outage)


async def serve_tcp(line: Answerer, host: str = "127.0.0.1", port: int = 0) -> TcpEnd:
    """Serve ``line`` on TCP (raw bytes); ``.url`` is a pyserial URL."""
    end = TcpEnd(line)
    await end.start(host, port)
    return end


async def serve_pty(line: Answerer, link: str) -> PtyEnd:
    """Serve ``line`` on a new pseudo-terminal reachable at the symlink ``link``."""
    end = PtyEnd(line, link)
    await end.start()
    return end
