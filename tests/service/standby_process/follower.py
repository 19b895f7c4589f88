"""A simulated drive line on TCP that logs every request it gets: on which connection, from
which process, and when (``time.monotonic()``, the clock the test and the masters share).

It stands for a serial-over-TCP gateway that admits several connections: two masters could
both reach the drives through it, and the log shows whether they ever did at the same time.
Each connection's process is found when it is accepted, from the kernel's socket tables:
the client's socket is one of the registered processes' open files (``owners``).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.serving.session import Session
from pkwbus.sim.serving.stats import SimStats

UNKNOWN = "?"


@dataclass(frozen=True)
class Request:
    conn: int  # the follower's number of the connection, from 1
    owner: str  # the name of the process that holds it (UNKNOWN: none registered)
    at: float  # time.monotonic() when it came


@dataclass
class Connection:
    number: int
    owner: str
    peer: tuple[str, int]
    opened: float
    closed: float | None = None


@dataclass
class Overlap:
    """Two connections that both transmitted within one stretch of time."""

    first: Connection
    second: Connection
    first_span: tuple[float, float]
    second_span: tuple[float, float]

    def __str__(self) -> str:
        a, b = self.first, self.second
        return (
            f"connection {a.number} ({a.owner}) sent from {self.first_span[0]:.3f} to "
            f"{self.first_span[1]:.3f} and connection {b.number} ({b.owner}) from "
            f"{self.second_span[0]:.3f} to {self.second_span[1]:.3f}"
        )


class _Logged:
    """The simulator as one connection's session sees it, logging each request."""

    def __init__(self, sim: Simulator, follower: Follower, conn: Connection) -> None:
        self._sim = sim
        self._follower = follower
        self._conn = conn

    @property
    def stats(self) -> SimStats:
        return self._sim.stats

    @property
    def timing(self) -> SimTiming:
        return self._sim.timing

    def deframer(self) -> Any:
        return self._sim.deframer()

    def is_request(self, event: object) -> bool:
        return self._sim.is_request(event)

    def request_size(self, event: object) -> int:
        return self._sim.request_size(event)

    def answer(self, request: Any, now: float | None = None) -> Answer | None:
        self._follower.requests.append(
            Request(self._conn.number, self._conn.owner, time.monotonic())
        )
        return self._sim.answer(request, now)


@dataclass
class Follower:
    """FC drives at ``addresses`` on ``socket://127.0.0.1:PORT`` (``url`` once started)."""

    addresses: Sequence[int] = (1,)
    owners: dict[int, str] = field(default_factory=dict)  # pid -> name, registered by the test
    requests: list[Request] = field(default_factory=list)
    connections: list[Connection] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.sim = Simulator(
            "fc", self.addresses, timing=SimTiming(response_delay=0.001), catalog="danfoss-fc"
        )
        self._server: asyncio.Server | None = None
        self._tasks: dict[asyncio.Task[None], asyncio.StreamWriter] = {}
        self.port = 0

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self.port}"

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._client, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
        for writer in list(self._tasks.values()):
            writer.transport.abort()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self._server is not None:
            await self._server.wait_closed()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")[:2]
        owner = owner_of(peer[1], self.port, self.owners)
        conn = Connection(len(self.connections) + 1, owner, peer, time.monotonic())
        self.connections.append(conn)
        task = asyncio.current_task()
        assert task is not None
        self._tasks[task] = writer
        session = Session(_Logged(self.sim, self, conn), writer.write)
        try:
            while data := await reader.read(4096):
                session.feed(data)
        except ConnectionError:
            pass
        finally:
            conn.closed = time.monotonic()
            self._tasks.pop(task, None)
            await session.close()
            writer.close()

    # --------------------------------------------------------------- reading the log

    def of(self, owner: str, since: float = 0.0) -> list[Request]:
        return [r for r in self.requests if r.owner == owner and r.at >= since]

    def first_of(self, owner: str, since: float = 0.0) -> Request | None:
        return next((r for r in self.requests if r.owner == owner and r.at >= since), None)

    def last_of(self, owner: str) -> Request | None:
        return next((r for r in reversed(self.requests) if r.owner == owner), None)

    def open_connections(self, owner: str | None = None) -> list[Connection]:
        return [c for c in self.connections if c.closed is None and owner in (None, c.owner)]

    def overlaps(self) -> list[Overlap]:
        """Every pair of connections whose requests interleave: see :func:`overlaps`."""
        return overlaps(self.requests, self.connections)

    def largest_gap(self, since: float, until: float) -> float:
        """The longest stretch within [since, until] with no request at all."""
        times = [since, *(r.at for r in self.requests if since < r.at < until), until]
        return max(b - a for a, b in itertools.pairwise(times))


def overlaps(requests: Iterable[Request], connections: Sequence[Connection]) -> list[Overlap]:
    """Pairs of connections that transmitted at the same instant: each connection's span runs
    from its first request to its last, and two spans that share any moment overlap. A master
    that reopened its port has two connections, one after the other; an idle connection left
    open (a standby that never transmits) has no span."""
    spans: dict[int, tuple[float, float]] = {}
    for r in requests:
        first, last = spans.get(r.conn, (r.at, r.at))
        spans[r.conn] = (min(first, r.at), max(last, r.at))
    by_number = {c.number: c for c in connections}
    ordered = sorted(spans.items(), key=lambda item: item[1])
    found = []
    for i, (conn, span) in enumerate(ordered):
        for other, other_span in ordered[i + 1 :]:
            if other_span[0] > span[1]:
                break
            found.append(Overlap(by_number[conn], by_number[other], span, other_span))
    return found


# --- which process holds a client socket ------------------------------------------------


def owner_of(local_port: int, remote_port: int, owners: dict[int, str]) -> str:
    """The name of the registered process with the loopback socket from ``local_port`` to
    ``remote_port`` open; UNKNOWN when none has (or the kernel tables cannot be read)."""
    inode = _socket_inode(local_port, remote_port)
    if inode is None:
        return UNKNOWN
    target = f"socket:[{inode}]"
    for pid, name in owners.items():
        with contextlib.suppress(OSError):
            for fd in os.listdir(f"/proc/{pid}/fd"):
                with contextlib.suppress(OSError):
                    if os.readlink(f"/proc/{pid}/fd/{fd}") == target:
                        return name
    return UNKNOWN


def _socket_inode(local_port: int, remote_port: int) -> str | None:
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with contextlib.suppress(OSError), open(table) as f:
            next(f)
            for line in f:
                fields = line.split()
                local, remote, inode = fields[1], fields[2], fields[9]
                if (
                    int(local.rsplit(":", 1)[1], 16) == local_port
                    and int(remote.rsplit(":", 1)[1], 16) == remote_port
                ):
                    return inode
    return None
