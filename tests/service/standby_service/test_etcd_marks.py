"""A line's drive-memory marks across a move, on a real etcd (Debian's etcd-server; skipped,
saying so, where it is missing): two service runtimes in process, each with its own history
database, one simulated drive that trips. The master tells the trip; stopped as SIGTERM
stops it, it hands the line over; the new master does not tell that trip again but tells a
new one, keeps the settings baseline the first took, and keeps the drive in maintenance."""

from __future__ import annotations

import asyncio
import json
import logging
import time
from contextlib import AsyncExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from pkwbus.service.assembly.build import assemble
from pkwbus.service.assembly.history import Memory, remember
from pkwbus.service.assembly.line_marks import MARK
from pkwbus.service.assembly.standby_lines import StandbyLines, etcd_engine
from pkwbus.service.config import parse_config
from pkwbus.service.history.settings_store import SettingsStore
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.runtime import Runtime
from pkwbus.sim import ModelConfig, SimTiming, Simulator
from tests.service.standby_process.etcd import Etcd

LEASE = 3.0
STEADY = ModelConfig(warning_rate=0.0, trip_rate=0.0)  # only the trips the test makes


@dataclass
class Instance:
    name: str
    runtime: Runtime
    gate: StandbyLines
    memory: Memory
    folder: Path

    def masters(self) -> bool:
        return "l1" in self.runtime.runners

    def watched(self) -> bool:
        logs = self.memory.logs
        return logs is not None and all(w.last_watch is not None for w in logs.watched)

    def baseline(self) -> tuple[float | None, float | None]:
        """d1's setting: since when its baseline holds, and when it was last read."""
        store = SettingsStore(self.folder / "history.sqlite")
        try:
            kept = store.load("d1")
        finally:
            store.close()
        rows = list((kept.rows or {}).values())
        return (rows[0].baseline_since, rows[0].seen) if rows else (None, None)


def config_text(url: str, endpoints: list[str], name: str, folder: Path) -> str:
    line = {
        "name": "l1", "port": url, "protocol": "fc", "baudrate": 115200, "timeout": "250ms",
        "retries": 0, "events_every": "1s", "describe": "off",
        "settings": {"every": "2s", "parameters": ["1-20"]},
        "drives": [{"name": "d1", "address": 1, "catalog": "danfoss-fc",
                    "poll": [{"parameter": "16-13", "every": "100ms"}]}],
    }  # fmt: skip
    standby = {"etcd": endpoints, "lease": f"{LEASE:g}s", "prefix": "/pkwbus-marks",
               "name": name, "advertise": f"http://{name}.example:9725"}  # fmt: skip
    audit = str(folder / "audit.sqlite")
    return json.dumps({"audit_db": audit, "standby": standby, "lines": [line]})


async def instance(stack: AsyncExitStack, url: str, etcd: Etcd, name: str, root: Path) -> Instance:
    folder = root / name
    folder.mkdir()
    config = parse_config(config_text(url, etcd.endpoints, name, folder), environ={})
    history = HistoryStore(config.history_path)
    stack.callback(history.close)
    runtime, parts = await assemble(config)
    memory = remember(config, runtime, history)
    gate = StandbyLines(config, runtime, parts, etcd_engine, memory)
    await runtime.start()
    stack.push_async_callback(runtime.stop)
    return Instance(name, runtime, gate, memory, folder)


async def until(condition: Any, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < end, "condition not met in time"
        await asyncio.sleep(0.05)


def told(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if " logged " in r.getMessage()]


async def test_a_move_neither_tells_old_entries_again_nor_loses_baseline_or_maintenance(
    etcd: Etcd, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)
    async with AsyncExitStack() as stack:
        sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.001), seed=3,
                        catalog="danfoss-fc", model=STEADY)  # fmt: skip
        end = await sim.serve_tcp("127.0.0.1", 0)
        stack.push_async_callback(end.close)
        a = await instance(stack, end.url, etcd, "a", tmp_path)
        await until(a.masters)
        b = await instance(stack, end.url, etcd, "b", tmp_path)
        await until(a.watched)
        sim.trip(1, 14)  # the first master tells it
        await until(lambda: len(told(caplog)) > 0)
        first = told(caplog)
        await until(lambda: a.baseline()[0] is not None)
        since, _ = a.baseline()
        a.runtime.runners["l1"].maintenance("d1", True, "bearing change")
        await until(lambda: "d1" in a.runtime.snapshot.maintenance)
        assert not b.masters()

        # SIGTERM's way: the lines stop, the marks are written last, the leases revoked.
        caplog.clear()
        stopped = time.time()
        await a.runtime.stop()
        mark = await b.gate.engine.marks.get("l1", MARK)  # type: ignore[attr-defined]
        assert mark is not None and len(mark) < 1_000_000
        await until(b.masters)
        held = b.runtime.snapshot.maintenance.get("d1")
        assert held is not None and held.reason == "bearing change"
        b.runtime.runners["l1"].maintenance("d1", False)  # nothing goes out to it until then
        await until(b.watched)
        assert told(caplog) == []  # a's trip is not told again
        await until(lambda: (b.baseline()[1] or 0) > stopped)  # b read d1's setting itself
        assert b.baseline()[0] == since  # a's baseline, not a new one

        sim.trip(1, 15)  # a new one is
        await until(lambda: len(told(caplog)) > 0)
        assert all(m not in first for m in told(caplog))
