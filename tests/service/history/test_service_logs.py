"""The drives' own logs through the running service and simulated drives on TCP: a trip
logged while pkwbus was stopped is found at its start, with the drive's time; a restart
repeats nothing; an entry from before a power cycle keeps no runtime time."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.assembly.history import remember
from pkwbus.service.config import parse_config
from pkwbus.service.history.store import DriveEvent, HistoryStore
from pkwbus.service.history.watch import LogWatcher
from pkwbus.sim import ModelConfig, SimTiming, Simulator

STEADY = ModelConfig(warning_rate=0.0, trip_rate=0.0)  # only the trips a test makes


@dataclass
class Plant:
    fc: Simulator
    uss: Simulator
    urls: dict[str, str]


@asynccontextmanager
async def plant() -> AsyncIterator[Plant]:
    async with AsyncExitStack() as stack:
        sims, urls = {}, {}
        for protocol, catalog in (("fc", "danfoss-fc"), ("uss", "siemens-g120")):
            sim = Simulator(protocol, [1], timing=SimTiming(response_delay=0.001), seed=3,
                            catalog=catalog, model=STEADY)  # fmt: skip
            end = await sim.serve_tcp("127.0.0.1", 0)
            stack.push_async_callback(end.close)
            sims[protocol], urls[protocol] = sim, end.url
        yield Plant(sims["fc"], sims["uss"], urls)


def config_text(p: Plant, folder: Path) -> str:
    return f"""
audit_db: {folder}/audit.sqlite
lines:
  - name: fc_line
    port: {p.urls["fc"]}
    protocol: fc
    baudrate: 115200
    events_every: 1s
    drives:
      - {{name: fan, address: 1, catalog: danfoss-fc, poll: [{{parameter: "16-13", every: 200ms}}]}}
  - name: uss_line
    port: {p.urls["uss"]}
    protocol: uss
    baudrate: 115200
    events_every: 1s
    drives:
      - {{name: pump, address: 1, catalog: siemens-g120,
         poll: [{{parameter: r0021, every: 200ms}}]}}
"""


@asynccontextmanager
async def service(p: Plant, folder: Path) -> AsyncIterator[LogWatcher]:
    """pkwbus run's runtime with its watch of the drives' logs, until the block ends."""
    async with watching(config_text(p, folder)) as watcher:
        yield watcher


@asynccontextmanager
async def watching(text: str) -> AsyncIterator[LogWatcher]:
    """The runtime of configuration ``text`` with its watch of the drives' logs."""
    config = parse_config(text, environ={})
    store = HistoryStore(config.history_path)
    runtime = await build_runtime(config)
    watcher = remember(config, runtime, store).logs
    assert watcher is not None
    await runtime.start()
    try:
        yield watcher
    finally:
        await runtime.stop()
        store.close()


async def until(check: Callable[[], bool], timeout: float = 30.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not check():
        assert loop.time() < end, "not within the time"
        await asyncio.sleep(0.05)


def kept(w: LogWatcher, drive: str) -> list[DriveEvent]:
    return w.store.latest(drive=drive)


def counted(w: LogWatcher) -> float:
    return sum(
        s.value
        for f in w.stream.counter.collect()
        for s in f.samples
        if s.name == "pkwbus_drive_events_total"
    )


async def test_a_trip_while_pkwbus_was_stopped_is_found_at_start_with_the_drives_time(
    tmp_path: Path,
) -> None:
    async with plant() as p:
        async with service(p, tmp_path) as w:
            await until(lambda: all(x.last_watch is not None for x in w.watched))
            assert counted(w) == 0
        tripped_at = time.time()
        p.uss.trip(1, 7801, value=-12)  # SINAMICS F07801, while nobody watches
        p.fc.trip(1, 13, value=2150)  # Danfoss alarm 13
        await asyncio.sleep(1.2)  # the drives' runtime goes on
        async with service(p, tmp_path) as w:
            await until(lambda: bool(kept(w, "pump")) and bool(kept(w, "fan")))
            (pump,) = kept(w, "pump")
            assert (pump.code, pump.number, pump.value) == ("F07801", 7801, -12)
            assert pump.time_source == "runtime" and pump.time is not None
            # The drive's runtime since the entry, taken back from when r2114 was read.
            assert pump.time == pytest.approx(tripped_at, abs=0.5)
            assert pump.seen >= tripped_at + 1.0
            (fan,) = kept(w, "fan")
            assert (fan.number, fan.value, fan.time_source) == (13, 2150, "seen")
            assert fan.time is None and fan.drive_time  # kept as the drive gave it
            await until(lambda: counted(w) == 2)  # each counted as it was stored


async def test_a_restart_repeats_nothing_and_a_new_trip_is_found_while_running(
    tmp_path: Path,
) -> None:
    async with plant() as p:
        p.uss.trip(1, 7801)
        async with service(p, tmp_path) as w:
            await until(lambda: len(kept(w, "pump")) == 1)
            p.uss.acknowledge(1)  # the case moves down: the same entry, elsewhere
            p.uss.trip(1, 30001, value=4)  # r0944 moves: found at the next watch
            await until(lambda: len(kept(w, "pump")) == 2)
            assert [e.number for e in kept(w, "pump")] == [30001, 7801]
        async with service(p, tmp_path) as w:
            await until(lambda: all(x.last_watch is not None for x in w.watched))
            assert len(kept(w, "pump")) == 2 and counted(w) == 2  # from the history, once


async def test_an_entry_from_before_a_power_cycle_is_kept_without_a_runtime_time(
    tmp_path: Path,
) -> None:
    async with plant() as p:
        # The drive has run an hour (a runtime no start of the service on a busy machine
        # reaches again after the power cycle, as half a second of sleep could be).
        p.uss.drives[1].model.runtime_ms += 3_600_000
        p.uss.trip(1, 7801)
        p.uss.power_cycle(1)  # its runtime restarts: the entry's time is from before
        async with service(p, tmp_path) as w:
            await until(lambda: len(kept(w, "pump")) == 1)
            (pump,) = kept(w, "pump")
            assert pump.time_source == "seen" and pump.time is None
            assert pump.drive_time.startswith("0 d 01:00:0")  # the runtime it was logged at


async def test_alarms_of_the_sinamics_alarm_buffer_are_found_once_with_the_drives_time(
    tmp_path: Path,
) -> None:
    """An alarm that came and went while pkwbus was stopped is found at its start; one that
    comes while it runs is found, and its going (into the history) is no new entry; one
    that came and went between two watches is found; a restart repeats none."""
    async with plant() as p:
        came_at = time.time()
        p.uss.warn(1, 1)  # A07409, while nobody watches
        await asyncio.sleep(0.3)
        p.uss.warn(1, None)  # gone into the history
        async with service(p, tmp_path) as w:
            await until(lambda: len(kept(w, "pump")) == 1)
            (first,) = kept(w, "pump")
            assert (first.kind, first.code, first.number) == ("alarm", "A07409", 7409)
            assert first.text == "Drive: U/f control, current limiting controller active"
            assert first.time_source == "runtime" and first.time is not None
            assert first.time == pytest.approx(came_at, abs=0.5)
            p.uss.warn(1, 9)  # A30030 comes while watched
            await until(lambda: len(kept(w, "pump")) == 2)
            p.uss.warn(1, 13)  # A30030 goes, A07402 comes
            p.uss.warn(1, None)  # and goes, before the next watch
            await until(lambda: len(kept(w, "pump")) == 3)
            await asyncio.sleep(2.5)  # two more watches: nothing more
            assert [e.number for e in kept(w, "pump")] == [7402, 30030, 7409]
            await until(lambda: counted(w) == 3)
        async with service(p, tmp_path) as w:
            await until(lambda: all(x.last_watch is not None for x in w.watched))
            assert len(kept(w, "pump")) == 3 and counted(w) == 3  # from the history, once
