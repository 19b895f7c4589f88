"""Lines over the simulator's real ends: TCP (socket://) and a pty, the production path."""

from __future__ import annotations

import asyncio
import inspect
import tempfile
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import pytest

from pkwbus.link import PortSettings
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.jobs import Job, JobKind, Priority
from pkwbus.master.planning.outcomes import Outcome
from pkwbus.master.planning.plan import DriveSpec, Finished, Send
from pkwbus.master.planning.planner import Planner
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.sim import SimFaults, SimTiming, Simulator


class Trace:
    def __init__(self) -> None:
        self.tx: list[bytes] = []
        self.rx: list[bytes] = []

    def __call__(self, direction: str, data: bytes) -> None:
        (self.tx if direction == "tx" else self.rx).append(data)


@asynccontextmanager
async def serve(sim: Simulator, end: str) -> AsyncIterator[str]:
    """Put ``sim`` on a TCP port or a pty; yield the port string a master opens."""
    if end == "tcp":
        server: Any = await sim.serve_tcp("127.0.0.1", 0)
        try:
            yield server.url
        finally:
            await server.close()
        return
    with tempfile.TemporaryDirectory() as tmp:
        server = await sim.serve_pty(str(Path(tmp) / "ttySIM"))
        try:
            yield server.path
        finally:
            await server.close()


@pytest.fixture(params=["tcp", "pty"])
def end(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def make_sim(protocol: str, addresses: list[int], **kw: Any) -> Simulator:
    kw.setdefault("timing", SimTiming(response_delay=0.0))
    kw.setdefault("seed", 7)
    return Simulator(protocol, addresses, **kw)


@asynccontextmanager
async def open_port(
    port: str, protocol: str, *, timeout: float = 0.5, **kw: Any
) -> AsyncIterator[tuple[TelegramPort, Trace]]:
    """A line on ``port``. The simulator answers from this test's own event loop: a
    loaded machine that holds the loop holds the answer too, so the default answer
    timeout is long enough for it (a test of timeouts gives its own)."""
    trace = Trace()
    line = TelegramPort(
        PortSettings(port, baudrate=115200, **kw), Bus(protocol), timeout=timeout, trace=trace
    )
    await line.open()
    try:
        yield line, trace
    finally:
        await line.close()


async def until(
    check: Callable[[], bool | Awaitable[bool]], timeout: float = 10.0, step: float = 0.01
) -> None:
    """Until ``check()`` holds (a coroutine function's answer awaited); the test fails
    after ``timeout`` seconds (generous: the machine may be loaded; waiting for the event,
    not a fixed time, keeps it short)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not (await got if inspect.isawaitable(got := check()) else got):
        assert loop.time() < end, f"{getattr(check, '__name__', 'check')}: not within {timeout} s"
        await asyncio.sleep(step)


async def run_job(
    line: TelegramPort,
    target: DriveTarget,
    request: pkw.PkwRequest,
    *,
    retries: int = 2,
    deadline: float = 2.0,
) -> Outcome:
    """One job on an open line, by the planner alone (no runner: the line's own tests)."""
    loop = asyncio.get_running_loop()
    until = loop.time() + deadline
    planner = Planner(
        [DriveSpec("drive", carrier_for(target))], poll_deadline=until, retries=retries
    )
    planner.line_up(loop.time())
    kind = JobKind.WRITE if request.is_write else JobKind.READ
    priority = Priority.WRITE if request.is_write else Priority.READ
    planner.submit(Job("drive", request, kind, priority, until), loop.time())
    while True:
        for event in planner.take_events():
            if isinstance(event, Finished) and isinstance(event.work, Job):
                return event.outcome
        action = planner.next_action(loop.time())
        if isinstance(action, Send):
            result = await line.exchange(action.address, action.telegram)
            planner.exchanged(action, result, loop.time())
        elif not planner.events:  # nothing to do before the job's deadline: it has ended
            await asyncio.sleep(max(0.0, min(action.until, until) - loop.time()))


__all__ = [
    "Callable",
    "SimFaults",
    "Trace",
    "make_sim",
    "open_port",
    "run_job",
    "serve",
    "until",
]
