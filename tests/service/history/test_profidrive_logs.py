"""The PROFIdrive fault buffer of DP drives of no catalog of their own, through the running
service and simulated slaves on TCP: an 8 x 1 buffer whose P948 is Unsigned16 "seconds
since the last fault occurred" (ABB RPBA-01) through the PPO's PKW words, each fault
placed by its age and listed once however many sweeps read it, older each time; an 8 x 8
buffer whose P948 is a TimeDifference with date (53) through data record 47, each fault
listed once with the time pkwbus first read it (no document says from when a
TimeDifference counts). A drive that refuses P950 is not watched, and says so once."""

from __future__ import annotations

import asyncio
import logging
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
from pkwbus.service.runtime import Runtime
from pkwbus.sim import ModelConfig, SimTiming
from pkwbus.sim.drives.profidrive_buffer import BufferKind
from pkwbus.sim.profibus.line import DpSimulator
from tests.service.history.test_service_logs import counted, kept, until

# Only the trips a test makes, acknowledged when it says; hours of runtime already (a
# trip's ms within its day then needs more than 16 bits).
STEADY = ModelConfig(warning_rate=0.0, trip_rate=0.0, trip_reset_seconds=0.0)
RUN_IN = ModelConfig(warning_rate=0.0, trip_rate=0.0, trip_reset_seconds=0.0, past_trips=1)


def dp_line(name: str, url: str, drive: str, address: int, access: str) -> str:
    """A DP line of one PROFIdrive slave of no catalog (``access``: its PPO and DP-V1)."""
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
         poll: [{{parameter: r0021, type: f32, every: 200ms}}]}}"""


def config_text(folder: Path, line: str) -> str:
    return f"audit_db: {folder}/audit.sqlite\nlines:{line}\n"


@dataclass
class Watching:
    runtime: Runtime
    logs: LogWatcher

    async def events(self, drive: str) -> list[dict[str, Any]]:
        """``GET /api/v1/events?drive=`` of the running service."""
        app = create_app(self.runtime)
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://pkwbus") as client:
            answer = await client.get("/api/v1/events", params={"drive": drive})
        assert answer.status_code == 200
        events: list[dict[str, Any]] = answer.json()["events"]
        return events


@asynccontextmanager
async def watching(text: str) -> AsyncIterator[Watching]:
    config = parse_config(text, environ={})
    store = HistoryStore(config.history_path)
    runtime = await build_runtime(config)
    watcher = remember(config, runtime, store).logs
    assert watcher is not None
    await runtime.start()
    try:
        yield Watching(runtime, watcher)
    finally:
        await runtime.stop()
        store.close()


@asynccontextmanager
async def slave(
    kind: BufferKind, address: int, model: ModelConfig, **dp: Any
) -> AsyncIterator[tuple[DpSimulator, str]]:
    sim = DpSimulator([address], timing=SimTiming(response_delay=0.001), model=model,
                      catalog=None, fault_buffers={address: kind}, **dp)  # fmt: skip
    end = await sim.serve_tcp("127.0.0.1", 0)
    try:
        yield sim, end.url
    finally:
        await end.close()


def parsed(stamp: str) -> float:
    """An ISO 8601 time of the API (``2026-11-17T08:00:10.000Z``) as seconds."""
    return datetime.fromisoformat(stamp).timestamp()


async def test_seconds_since_each_fault_through_the_pkw_words_each_listed_once(
    tmp_path: Path,
) -> None:
    async with slave(BufferKind(8, 1, 6), 8, STEADY, ppo_number=1) as (sim, url):
        drive = sim.drives[8]
        first_at = time.time()
        drive.trip(21, sim.clock(), value=3)
        drive.acknowledge(sim.clock())
        await asyncio.sleep(1.2)
        second_at = time.time()
        drive.trip(22, sim.clock(), value=4)  # active: [0]; the first at [1]
        text = config_text(tmp_path, dp_line("dp1", url, "press", 8, "ppo: 1"))
        async with watching(text) as w:
            (watched,) = w.logs.watched
            assert watched.log.name == "PROFIdrive fault buffer"
            await until(lambda: len(kept(w.logs, "press")) == 2, 60)
            await asyncio.sleep(2.5)  # both older now, by more than their slack
            third_at = time.time()
            drive.acknowledge(sim.clock())
            drive.trip(23, sim.clock(), value=5)  # P944 changes: a sweep reads all three
            await until(lambda: len(kept(w.logs, "press")) == 3, 60)
            await asyncio.sleep(2.5)
            drive.acknowledge(sim.clock())  # and another sweep, older still
            await until(lambda: watched.last_watch == (drive.model.profidrive.counter,), 30)
            listed = await w.events("press")
            await until(lambda: counted(w.logs) == 3)
    assert [(e["code"], e["value"]) for e in listed] == [("23", 5), ("22", 4), ("21", 3)]
    for event, at in zip(listed, (third_at, second_at, first_at), strict=True):
        assert event["kind"] == "fault" and event["time_source"] == "runtime"
        assert parsed(event["time"]) == pytest.approx(at, abs=1.5)
        assert event["drive_time"].endswith("s before it was read")


async def test_time_differences_through_data_record_47_each_listed_once_when_seen(
    tmp_path: Path,
) -> None:
    async with slave(BufferKind(8, 8, 53), 9, STEADY, ppo_number=3, dpv1=True) as (sim, url):
        drive = sim.drives[9]
        drive.trip(31, sim.clock(), value=-7)
        drive.trip(32, sim.clock(), value=8)  # the same situation
        drive.acknowledge(sim.clock())
        text = config_text(tmp_path, dp_line("dp2", url, "hoist", 9, "ppo: 3, dpv1: true"))
        async with watching(text) as w:
            await until(lambda: len(kept(w.logs, "hoist")) == 2, 60)
            drive.trip(33, sim.clock(), value=9)
            await until(lambda: len(kept(w.logs, "hoist")) == 3, 60)
            listed = await w.events("hoist")
    by_code = {e["code"]: e for e in listed}
    assert sorted(by_code) == ["31", "32", "33"] and len(listed) == 3
    assert (by_code["31"]["value"], by_code["32"]["value"]) == (-7, 8)
    for event in listed:
        assert event["time_source"] == "seen" and event["time"] == event["seen"]
        assert event["drive_time"].startswith("0 d 00:00:")  # the runtime at the trip


async def test_a_time_difference_past_65_536_ms_in_its_day_keeps_its_ms(tmp_path: Path) -> None:
    async with slave(BufferKind(8, 8, 53), 9, RUN_IN, ppo_number=3, dpv1=True) as (sim, url):
        drive = sim.drives[9]
        ms = drive.model.runtime_ms
        drive.trip(31, sim.clock(), value=1)
        text = config_text(tmp_path, dp_line("dp2", url, "hoist", 9, "ppo: 3, dpv1: true"))
        async with watching(text) as w:
            await until(lambda: len(kept(w.logs, "hoist")) == 1, 60)
            (event,) = kept(w.logs, "hoist")
    hours = ms // 3_600_000
    assert hours >= 1 and event.drive_time.startswith(f"0 d {hours:02d}:")


async def test_a_drive_that_refuses_p950_is_not_watched_and_says_so_once(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    sim = DpSimulator([8], timing=SimTiming(response_delay=0.001), model=STEADY, catalog=None)
    end = await sim.serve_tcp("127.0.0.1", 0)  # the drive's table has r0944, no P950
    try:
        text = config_text(tmp_path, dp_line("dp1", end.url, "press", 8, "ppo: 1"))
        with caplog.at_level(logging.WARNING, logger="pkwbus.service.history"):
            async with watching(text) as w:
                (task,) = w.logs._tasks
                await until(task.done, 60)
                await asyncio.sleep(1.5)
    finally:
        await end.close()
    said = [r.getMessage() for r in caplog.records if "not watched" in r.getMessage()]
    assert said == [
        "drive press: its PROFIdrive fault buffer is not watched: the drive refuses P950, the"
        " buffer's fault situations and messages"
    ]
