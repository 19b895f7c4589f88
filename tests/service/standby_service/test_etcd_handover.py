"""Two service runtimes in hot standby on a real etcd (Debian's etcd-server; skipped, saying
so, where it is missing) and one simulated line on TCP, in process: exactly one of them
opens the port and polls, the other keeps it closed; the master stopped as SIGTERM stops it
(its port closed, then its lease revoked) hands the line over at once, far sooner than the
lease would expire."""

from __future__ import annotations

import asyncio
import json
import time
from contextlib import AsyncExitStack
from dataclasses import dataclass
from typing import Any

from pkwbus.protocol.serial.telegram import Telegram
from pkwbus.service.assembly.build import Parts, assemble
from pkwbus.service.assembly.standby_lines import StandbyLines, etcd_engine
from pkwbus.service.config import parse_config
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.serving.ends import TcpEnd
from tests.service.standby_process.etcd import Etcd

# Long enough that a handover by the lease's expiry (lease, then a campaign) could not pass
# for one by the revoke: the handover must come well within it.
LEASE = 10.0


@dataclass
class Instance:
    name: str
    runtime: Runtime
    parts: Parts
    gate: StandbyLines

    def masters(self) -> bool:
        return "l1" in self.runtime.runners

    def polled_since(self, since: float) -> bool:
        """A value of d1 read at or after ``since`` (Unix time)."""
        reading = self.runtime.snapshot.readings.get(("d1", "16-13", 0))
        return reading is not None and reading.timestamp >= since


def config_text(url: str, endpoints: list[str], name: str) -> str:
    line = {
        "name": "l1", "port": url, "protocol": "fc", "baudrate": 115200, "timeout": "250ms",
        "retries": 0, "alarms": "off", "settings": "off", "events": "off", "counters": "off",
        "drives": [{"name": "d1", "address": 1, "catalog": "danfoss-fc",
                    "poll": [{"parameter": "16-13", "every": "50ms"}]}],
    }  # fmt: skip
    standby = {"etcd": endpoints, "lease": f"{LEASE:g}s", "prefix": "/pkwbus-e2e",
               "name": name, "advertise": f"http://{name}.example:9725"}  # fmt: skip
    return json.dumps({"audit_db": ":memory:", "standby": standby, "lines": [line]})


async def instance(stack: AsyncExitStack, url: str, etcd: Etcd, name: str) -> Instance:
    config = parse_config(config_text(url, etcd.endpoints, name), environ={})
    assert config.standby is not None
    runtime, parts = await assemble(config)
    gate = StandbyLines(config, runtime, parts, etcd_engine)
    await runtime.start()
    stack.push_async_callback(runtime.stop)
    return Instance(name, runtime, parts, gate)


async def until(condition: Any, timeout: float) -> float:
    """Wait for ``condition``; the time.monotonic() it was first seen true."""
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, "condition not met in time"
        await asyncio.sleep(0.02)
    return time.monotonic()


async def test_one_polls_and_a_stopped_master_hands_the_line_over_at_once(etcd: Etcd) -> None:
    heard: list[float] = []
    open_seen: list[int] = []
    async with AsyncExitStack() as stack:
        sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.002), seed=2,
                        catalog="danfoss-fc")  # fmt: skip
        answer = sim.answer

        def hear(t: Telegram, now: float | None = None) -> Any:
            heard.append(time.monotonic())
            return answer(t, now)

        sim.answer = hear  # type: ignore[method-assign,assignment]
        end: TcpEnd = await sim.serve_tcp("127.0.0.1", 0)
        stack.push_async_callback(end.close)

        async def watch_connections() -> None:
            while True:
                open_seen.append(len(end._clients))
                await asyncio.sleep(0.01)

        watcher = asyncio.create_task(watch_connections())
        stack.callback(watcher.cancel)
        a = await instance(stack, end.url, etcd, "a")
        b = await instance(stack, end.url, etcd, "b")

        # Exactly one masters the line, and it alone polls; the other keeps the port closed.
        await until(lambda: a.masters() or b.masters(), 30.0)
        master, standby = (a, b) if a.masters() else (b, a)
        await until(lambda: master.polled_since(0.0), 30.0)
        await asyncio.sleep(1.0)
        assert master.masters() and not standby.masters()
        assert not standby.runtime.snapshot.readings and not standby.runtime.snapshot.lines
        assert end.connections == 1 and len(end._clients) == 1
        assert master.gate.master_of("l1") is not None
        seen = standby.gate.master_of("l1")
        assert seen is not None and seen.name == master.name
        assert seen.url == f"http://{master.name}.example:9725"
        assert master.gate.here("l1") and not standby.gate.here("l1")

        # SIGTERM's way: the lines stop (the port closes), then the leases are revoked.
        stopped, wall = time.monotonic(), time.time()
        await master.runtime.stop()
        took = await until(lambda: standby.polled_since(wall), LEASE + 20) - stopped
        print(f"handover: the standby polled {took:.2f} s after the master's stop began")
        assert took < LEASE / 2, f"the standby polled {took:.2f} s after the stop"
        assert standby.masters() and end.connections == 2
        # Never two connections open at once: the old one was closed before the new one.
        assert max(open_seen) == 1, open_seen
        last_of_old = max(t for t in heard if t < stopped + 0.001)
        assert last_of_old <= stopped + 0.5
