"""The MICROMASTER 4 fault buffer through the running service and simulated drives of
catalog siemens-mm4, on USS and on PROFIBUS DP (the PPO's PKW words, data record 47): each
trip, before pkwbus started, while it ran and while it was stopped, is in
``GET /api/v1/events`` once, its time from the drive's run time counter (r2114, whole
seconds: within a second, and the time an answer takes); with the AOP clock P2115 set,
whose encoding is not known, ``seen``."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx
import pytest

from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.assembly.history import remember
from pkwbus.service.config import parse_config
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.history.watch import LogWatcher
from pkwbus.service.http.api import create_app
from pkwbus.sim import ModelConfig, SimTiming, Simulator
from pkwbus.sim.profibus.line import DpSimulator
from tests.service.history.test_service_logs import until

STEADY = ModelConfig(warning_rate=0.0, trip_rate=0.0, trip_reset_seconds=0.0)
TIMING = SimTiming(response_delay=0.001)
WITHIN = 1.25  # the counter's second, and the time an answer takes


@dataclass
class Service:
    watcher: LogWatcher
    client: httpx.AsyncClient

    async def events(self, drive: str) -> list[dict[str, Any]]:
        answer = await self.client.get("/api/v1/events", params={"drive": drive})
        assert answer.status_code == 200
        found: list[dict[str, Any]] = answer.json()["events"]
        return found


@asynccontextmanager
async def service(text: str) -> AsyncIterator[Service]:
    """pkwbus run's runtime of configuration ``text``, its watch and its HTTP API."""
    config = parse_config(text, environ={})
    store = HistoryStore(config.history_path)
    runtime = await build_runtime(config)
    watcher = remember(config, runtime, store).logs
    assert watcher is not None
    await runtime.start()
    app = create_app(runtime)
    try:
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://pkwbus") as client:
            yield Service(watcher, client)
    finally:
        await runtime.stop()
        store.close()


def uss_config(url: str, folder: Path) -> str:
    return f"""
audit_db: {folder}/audit.sqlite
lines:
  - name: uss_line
    port: {url}
    protocol: uss
    baudrate: 115200
    events_every: 1s
    drives:
      - {{name: pump, address: 1, catalog: siemens-mm4}}
      - {{name: clocked, address: 2, catalog: siemens-mm4}}
"""


def stamp(text: str) -> float:
    return datetime.fromisoformat(text).timestamp()


async def found(s: Service, drive: str, count: int) -> dict[str, dict[str, Any]]:
    """The drive's events, by code, once ``count`` are there (no code twice)."""
    events: list[dict[str, Any]] = []

    async def look() -> bool:
        events[:] = await s.events(drive)
        return len(events) >= count

    loop = asyncio.get_running_loop()
    end = loop.time() + 30
    while not await look():
        assert loop.time() < end, f"{drive}: {len(events)} events, not {count}"
        await asyncio.sleep(0.1)
    by_code = {e["code"]: e for e in events}
    assert len(by_code) == len(events) == count, events
    return by_code


async def test_each_trip_once_with_the_counters_time_and_seen_with_the_aop_clock(
    tmp_path: Path,
) -> None:
    sim = Simulator("uss", [1, 2], timing=TIMING, seed=3, catalog="siemens-mm4", model=STEADY)
    end = await sim.serve_tcp("127.0.0.1", 0)
    sim.drives[2].set_value(2115, 0x1234, 0)  # its AOP clock is set
    tripped: dict[str, float] = {}

    def trip(address: int, code: int) -> None:
        tripped[str(code)] = time.time()
        sim.trip(address, code, value=code * 10)

    try:
        await asyncio.sleep(1.1)  # the drives have run a while
        trip(1, 3)  # before pkwbus starts: a trip of two faults, acknowledged
        trip(1, 4)
        sim.acknowledge(1)
        trip(2, 30)
        async with service(uss_config(end.url, tmp_path)) as s:
            await found(s, "pump", 2)
            await asyncio.sleep(0.6)
            trip(1, 5)  # while it runs
            trip(2, 31)
            await found(s, "pump", 3)
            sim.acknowledge(1)
            sim.acknowledge(2)
        trip(1, 6)  # while it is stopped
        await asyncio.sleep(1.2)
        async with service(uss_config(end.url, tmp_path)) as s:
            pump = await found(s, "pump", 4)
            clocked = await found(s, "clocked", 2)
            await asyncio.sleep(2.5)  # more watches: nothing twice
            assert len(await s.events("pump")) == 4 and len(await s.events("clocked")) == 2
    finally:
        await end.close()
    for code, event in pump.items():
        assert event["time_source"] == "runtime" and event["value"] == int(code) * 10
        trip_time = tripped["3" if code == "4" else code]  # a trip's second fault: its time
        assert stamp(event["time"]) == pytest.approx(trip_time, abs=WITHIN)
    for event in clocked.values():
        assert event["time_source"] == "seen" and event["time"] == event["seen"]
        assert event["drive_time"]  # P2115's words, kept as the drive gave them


def dp_config(ppo_url: str, record_url: str, folder: Path) -> str:
    def line(name: str, url: str, drive: str, address: int, access: str) -> str:
        return f"""
  - name: {name}
    port: "{url}"
    protocol: profibus
    baudrate: 93750
    slot_time: 50ms
    watchdog: 2s
    events_every: 1s
    drives:
      - {{name: {drive}, address: {address}, dialect: profidrive, ident: 0x80B5, {access},
         catalog: siemens-mm4}}"""

    return (
        f"audit_db: {folder}/audit.sqlite\nlines:"
        + line("dp1", ppo_url, "mixer", 8, "ppo: 1")
        + line("dp2", record_url, "fan", 9, "ppo: 3, dpv1: true")
        + "\n"
    )


async def test_on_profibus_through_the_ppo_and_data_record_47(tmp_path: Path) -> None:
    ppo = DpSimulator([8], timing=TIMING, model=STEADY, catalog="siemens-mm4")
    record = DpSimulator(
        [9], timing=TIMING, model=STEADY, ppo_number=3, dpv1=True, catalog="siemens-mm4"
    )
    ppo_end = await ppo.serve_tcp("127.0.0.1", 0)
    record_end = await record.serve_tcp("127.0.0.1", 0)
    try:
        await asyncio.sleep(1.1)
        tripped_at = time.time()
        ppo.drives[8].trip(7, ppo.clock(), value=70)
        record.drives[9].trip(8, record.clock(), value=80)
        async with service(dp_config(ppo_end.url, record_end.url, tmp_path)) as s:
            logs = {(x.drive, x.log.name) for x in s.watcher.watched}
            assert logs == {(d, "MICROMASTER 4 fault buffer") for d in ("mixer", "fan")}
            await until(lambda: all(x.last_watch is not None for x in s.watcher.watched), 60)
            (mixer,) = (await found(s, "mixer", 1)).values()
            (fan,) = (await found(s, "fan", 1)).values()
    finally:
        await ppo_end.close()
        await record_end.close()
    assert (mixer["code"], mixer["value"], fan["code"], fan["value"]) == ("7", 70, "8", 80)
    for event in (mixer, fan):
        assert event["time_source"] == "runtime"
        assert stamp(event["time"]) == pytest.approx(tripped_at, abs=WITHIN)
