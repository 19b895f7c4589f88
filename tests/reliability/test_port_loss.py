"""Port loss: the gateway or the pty vanishes and returns while the service runs.

The line comes back within a couple of seconds of its port returning,
``pkwbus_line_up`` (``snapshot.lines``) tells the truth meanwhile, a second
line on another simulator never notices, and no task is left behind.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming, Simulator

from .helpers import config_text, fc_line, wait_for

COMES_BACK = 2.5  # seconds from the port's return to a fresh value on the line
POLLS = ["16-13", "16-14"]


def fresh_value(runtime: Runtime, drive: str, since: float) -> bool:
    return any(
        key[0] == drive and reading.timestamp > since
        for key, reading in list(runtime.snapshot.readings.items())
    )


class Watch:
    """Samples the other line while the first one loses its port."""

    def __init__(self, runtime: Runtime, line: str, sim: Simulator) -> None:
        self.runtime = runtime
        self.line = line
        self.sim = sim
        self.down_seen: list[float] = []
        self.rates: list[float] = []
        self._task = asyncio.create_task(self._run())

    async def _run(self) -> None:
        last = self.sim.stats.line["requests"]
        while True:
            await asyncio.sleep(0.25)
            now = self.sim.stats.line["requests"]
            self.rates.append((now - last) / 0.25)
            last = now
            if not self.runtime.snapshot.lines.get(self.line):
                self.down_seen.append(time.monotonic())

    async def stop(self) -> None:
        self._task.cancel()
        await asyncio.gather(self._task, return_exceptions=True)


async def start(port_a: str, url_b: str) -> Runtime:
    text = config_text(
        [
            fc_line("a", port_a, [1], POLLS, every="50ms", timeout="100ms"),
            fc_line("b", url_b, [1], POLLS, every="50ms", timeout="100ms"),
        ]
    )
    runtime = await build_runtime(parse_config(text, environ={}))
    await runtime.start()
    return runtime


async def lose_and_return(
    runtime: Runtime, close: Any, reopen: Any, cycles: int, outage: float
) -> list[float]:
    """Take line a's port away ``cycles`` times; the seconds each return took."""
    took = []
    for _ in range(cycles):
        await close()
        await wait_for(lambda: not runtime.snapshot.lines["a"], 2.0)
        await asyncio.sleep(outage)
        assert not runtime.snapshot.lines["a"], "line a reported up while its port is gone"
        returned = time.time()
        await reopen()
        took.append(
            await wait_for(
                lambda since=returned: (
                    runtime.snapshot.lines["a"] and fresh_value(runtime, "a_d1", since)
                ),
                COMES_BACK + 5,
            )
        )
    return took


async def check_other_line(runtime: Runtime, watch: Watch, baseline: float) -> None:
    await watch.stop()
    assert not watch.down_seen, "line b went down while line a lost its port"
    assert runtime.snapshot.lines["b"]
    # Line b's poll rate stays: no quarter second of it below half its rate alone.
    # (Generous: the machine is shared; a stall of line b would show as 0.)
    slow = [r for r in watch.rates if r < baseline / 2]
    assert len(slow) <= len(watch.rates) // 10, (baseline, watch.rates)
    assert min(watch.rates) > 0, watch.rates


async def baseline_rate(sim: Simulator) -> float:
    before = sim.stats.line["requests"]
    await asyncio.sleep(1.0)
    return float(sim.stats.line["requests"] - before)


async def test_tcp_gateway_vanishes_and_returns_20_times() -> None:
    tasks_before = len(asyncio.all_tasks())
    sim_a = Simulator("fc", [1], timing=SimTiming(0.002), seed=1)
    sim_b = Simulator("fc", [1], timing=SimTiming(0.002), seed=2)
    ends: dict[str, Any] = {
        "a": await sim_a.serve_tcp("127.0.0.1", 0),
        "b": await sim_b.serve_tcp("127.0.0.1", 0),
    }
    port = ends["a"].port
    runtime = await start(ends["a"].url, ends["b"].url)
    try:
        await wait_for(lambda: fresh_value(runtime, "a_d1", 0), 5.0)
        baseline = await baseline_rate(sim_b)
        watch = Watch(runtime, "b", sim_b)

        async def close() -> None:
            await ends["a"].close()

        async def reopen() -> None:
            ends["a"] = await sim_a.serve_tcp("127.0.0.1", port)

        took = await lose_and_return(runtime, close, reopen, 20, 0.2)
        await check_other_line(runtime, watch, baseline)
        assert max(took) < COMES_BACK, took
    finally:
        await runtime.stop()
        for end in ends.values():
            await end.close()
    await asyncio.sleep(0.05)
    assert len(asyncio.all_tasks()) == tasks_before, asyncio.all_tasks()


async def test_pty_disappears_and_reappears(tmp_path: Path) -> None:
    tasks_before = len(asyncio.all_tasks())
    path = str(tmp_path / "ttyGW")
    sim_a = Simulator("fc", [1], timing=SimTiming(0.002), seed=1)
    sim_b = Simulator("fc", [1], timing=SimTiming(0.002), seed=2)
    ends: dict[str, Any] = {"a": await sim_a.serve_pty(path)}
    ends["b"] = await sim_b.serve_tcp("127.0.0.1", 0)
    runtime = await start(path, ends["b"].url)
    try:
        await wait_for(lambda: fresh_value(runtime, "a_d1", 0), 5.0)
        baseline = await baseline_rate(sim_b)
        watch = Watch(runtime, "b", sim_b)

        async def close() -> None:
            await ends["a"].close()

        async def reopen() -> None:
            ends["a"] = await sim_a.serve_pty(path)

        took = await lose_and_return(runtime, close, reopen, 4, 0.3)
        await check_other_line(runtime, watch, baseline)
        assert max(took) < COMES_BACK, took
    finally:
        await runtime.stop()
        for end in ends.values():
            await end.close()
    await asyncio.sleep(0.05)
    assert len(asyncio.all_tasks()) == tasks_before, asyncio.all_tasks()
