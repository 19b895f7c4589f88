"""A hot-standby engine the test drives (the contract of service.standby.Standby), and a
service in standby over simulated FC drives on TCP, in process, with its HTTP app."""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import httpx

from pkwbus.link.fence import FENCE_CLOCK
from pkwbus.protocol.buses import decode_adr
from pkwbus.protocol.serial.telegram import Telegram
from pkwbus.service.assembly.build import Parts, assemble
from pkwbus.service.assembly.reload import Reloader
from pkwbus.service.assembly.standby_lines import StandbyLines
from pkwbus.service.config import Config, parse_config
from pkwbus.service.http.api import build_api
from pkwbus.service.metrics.exposition import render
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.serving.ends import TcpEnd

TOKEN = "s3cret-Write-Token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
SECTION = object()  # the configuration's standby section: the fake engine does not read it


@dataclass(frozen=True)
class Master:
    name: str
    url: str | None


class Fence:
    """A line's lease fence: open until ``until`` (0.0 while not held)."""

    def __init__(self) -> None:
        self.until = 0.0

    def open_until(self) -> float:
        return self.until


class FakeEngine:
    """The engine of the contract, its campaign played by the test: :meth:`grant` (this
    instance won the line), :meth:`lose` (another did, or nobody), :meth:`expire` (the
    fence closes without a word, as a renewal that stopped)."""

    def __init__(
        self, section: object, lines: Sequence[str], on_change: Callable[[str, bool], None],
        *, name: str = "here",
    ) -> None:  # fmt: skip
        assert section is SECTION
        self.name = name
        self.lines = list(lines)
        self.on_change = on_change
        self.fences: dict[str, Fence] = {}
        self.masters: dict[str, Master] = {}
        self.taken: dict[str, int] = {}
        self.etcd_up = False
        self.started = self.stopped = False
        self.calls: list[str] = []
        self.set: list[list[str]] = []
        self.at_stop: Callable[[], None] | None = None  # what the test checks when stop comes

    async def start(self) -> None:
        self.started = True
        self.etcd_up = True
        self.calls.append("start")

    async def stop(self, *, revoke_lines: bool = True) -> None:
        self.revoked_lines = revoke_lines
        if self.at_stop is not None:
            self.at_stop()
        self.stopped = True
        self.calls.append("stop")
        for line in list(self.fences):
            self.fences[line].until = 0.0
            self.masters.pop(line, None)

    def fence(self, line: str) -> Fence:
        return self.fences.setdefault(line, Fence())

    def holds(self, line: str) -> bool:
        return FENCE_CLOCK() < self.fence(line).open_until()

    def master_of(self, line: str) -> Master | None:
        return self.masters.get(line)

    def takeovers(self, line: str) -> int:
        return self.taken.get(line, 0)

    def set_lines(self, lines: Sequence[str]) -> None:
        self.set.append(list(lines))
        self.lines = list(lines)

    # -- the test's side

    def grant(self, line: str) -> None:
        self.fence(line).until = math.inf
        self.masters[line] = Master(self.name, "http://here.example:9725")
        self.taken[line] = self.taken.get(line, 0) + 1
        self.on_change(line, True)

    def lose(self, line: str, to: Master | None = None) -> None:
        self.fence(line).until = 0.0
        if to is None:
            self.masters.pop(line, None)
        else:
            self.masters[line] = to
        self.on_change(line, False)

    def expire(self, line: str) -> None:
        self.fence(line).until = FENCE_CLOCK() - 0.001


def drive(name: str, address: int) -> dict[str, Any]:
    return {"name": name, "address": address, "catalog": "danfoss-fc",
            "poll": [{"parameter": "16-13", "every": "100ms"}],
            "writable": ["3-41"]}  # fmt: skip


def line(name: str, url: str, drives: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "name": name, "port": url, "protocol": "fc", "baudrate": 115200, "timeout": "500ms",
        "retries": 0, "alarms": "off", "settings": "off", "events": "off", "counters": "off",
        "drives": drives,
    }  # fmt: skip


@dataclass
class Service:
    """Two lines, l1 (drives a1, a2) and l2 (b1), each on its own simulated gateway."""

    ends: dict[str, TcpEnd]
    heard: list[tuple[float, str, int]]  # (FENCE_CLOCK(), line, address) of each request
    runtime: Runtime
    parts: Parts
    gate: StandbyLines
    engine: FakeEngine
    client: httpx.AsyncClient
    reloader: Reloader
    text: list[str] = field(default_factory=list)
    api: Any = None  # the HTTP app's Api (its audit writer)

    async def metrics(self) -> str:
        return (await render(self.parts.registry)).decode()

    def requests(self, line: str, since: float = 0.0) -> int:
        return sum(1 for t, n, _ in self.heard if n == line and t >= since)

    def open_connections(self, line: str) -> int:
        return len(self.ends[line]._clients)


def standby_config(text: str) -> Config:
    """The configuration ``text`` with a standby section (the fake engine's)."""
    return parse_config(text, environ={}).model_copy(update={"standby": SECTION})


def config_text(urls: dict[str, str], lines: Sequence[str] = ("l1", "l2")) -> str:
    drives = {"l1": [drive("a1", 1), drive("a2", 2)], "l2": [drive("b1", 1)],
              "l3": [drive("c1", 1)]}  # fmt: skip
    return json.dumps({
        "audit_db": ":memory:",
        "lines": [line(n, urls[n], drives[n]) for n in lines],
    })  # fmt: skip


@asynccontextmanager
async def service(names: Sequence[str] = ("l1", "l2", "l3")) -> AsyncIterator[Service]:
    """The service in standby, started: it masters nothing until the test grants a line."""
    heard: list[tuple[float, str, int]] = []
    async with AsyncExitStack() as stack:
        ends: dict[str, TcpEnd] = {}
        for n in names:
            sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.002), seed=2,
                            catalog="danfoss-fc")  # fmt: skip
            answer = sim.answer

            def hear(t: Telegram, now: float | None = None, n: str = n, sim: Any = sim,
                     answer: Any = answer) -> Any:  # fmt: skip
                heard.append((FENCE_CLOCK(), n, decode_adr(sim.protocol, t.adr).address))
                return answer(t, now)

            sim.answer = hear  # type: ignore[method-assign,assignment]
            end = await sim.serve_tcp("127.0.0.1", 0)
            stack.push_async_callback(end.close)
            ends[n] = end
        urls = {n: e.url for n, e in ends.items()}
        text = [config_text(urls)]

        def reread() -> Config:
            return standby_config(text[0])

        config = reread()
        runtime, parts = await assemble(config)
        engines: list[FakeEngine] = []

        def factory(section: Any, lines: Sequence[str], on_change: Any) -> FakeEngine:
            engines.append(FakeEngine(section, lines, on_change))
            return engines[-1]

        gate = StandbyLines(config, runtime, parts, factory)
        reloader = Reloader(config, reread, runtime, parts, gate=gate)
        api = build_api(runtime, write_token=TOKEN)
        await runtime.start()
        stack.push_async_callback(runtime.stop)
        transport = httpx.ASGITransport(app=api.app)
        client = await stack.enter_async_context(
            httpx.AsyncClient(transport=transport, base_url="http://pkwbus")
        )
        yield Service(ends, heard, runtime, parts, gate, engines[0], client, reloader, text, api)


@asynccontextmanager
async def single() -> AsyncIterator[tuple[Runtime, Any, httpx.AsyncClient]]:
    """The same two lines in one instance (no standby section), started."""
    async with AsyncExitStack() as stack:
        urls = {}
        for n in ("l1", "l2"):
            sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.002), seed=2,
                            catalog="danfoss-fc")  # fmt: skip
            end = await sim.serve_tcp("127.0.0.1", 0)
            stack.push_async_callback(end.close)
            urls[n] = end.url
        config = parse_config(config_text(urls), environ={})
        runtime, parts = await assemble(config)
        api = build_api(runtime, write_token=TOKEN)
        await runtime.start()
        stack.push_async_callback(runtime.stop)
        transport = httpx.ASGITransport(app=api.app)
        client = await stack.enter_async_context(
            httpx.AsyncClient(transport=transport, base_url="http://pkwbus")
        )
        yield runtime, parts.registry, client


async def until(condition: Callable[[], bool], timeout: float = 30.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not condition():
        assert loop.time() < end, "condition not met in time"
        await asyncio.sleep(0.02)
