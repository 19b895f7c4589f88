"""The watch of a drive's own log through a (fake) line: cheap while nothing changes, a
sweep when the counter moves, at start and when the drive comes back; each entry kept and
counted once over restarts; times from the drive's runtime base, or ``seen``."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from pathlib import Path

import pytest
from prometheus_client import CollectorRegistry

from pkwbus.catalog.alarms import CodeTable, alarm_table
from pkwbus.master.planning.jobs import Job, JobResult, Priority
from pkwbus.master.planning.outcomes import Answered, Rejected, TimedOut
from pkwbus.master.planning.plan import HealthChanged
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.logs import (
    DANFOSS_ALARM_LOG,
    MICROMASTER_FAULT_BUFFER,
    SINAMICS_ALARM_BUFFER,
    SINAMICS_FAULT_BUFFER,
    DriveLog,
    Read,
    Runtime,
)
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.history.stream import EventStream
from pkwbus.service.history.watch import WHOLE_EVERY, LogWatcher, Watched, was_off
from tests.protocol.logs.test_alarm_buffer import AlarmBuffer
from tests.protocol.logs.test_logs import AlarmLog, FaultBuffer
from tests.protocol.logs.test_micromaster import Mm4Buffer

EVERY = 0.02


class FakeLine:
    """A line task whose one drive answers background reads from ``drive``."""

    name = "l1"

    def __init__(self, drive: Callable[[Read], int | None]) -> None:
        self.drive = drive
        self.jobs: list[Job] = []
        self.down = False

    def submit(self, job: Job) -> None:
        assert job.priority is Priority.BACKGROUND
        self.jobs.append(job)
        request = job.request
        value = self.drive(Read(request.pnu, request.subindex))
        if self.down:
            result = JobResult(TimedOut("no answer"))
        elif value is None:
            result = JobResult(Rejected(0, "no such parameter", "pnu"))
        else:
            raw = value & 0xFFFFFFFF
            response = pkw.ValueResponse(2, request.pnu, request.subindex, raw, pkw.Width.DWORD)
            result = JobResult(Answered(response))
        job.resolve(result)

    def stop(self) -> None: ...

    async def run(self) -> None: ...


def watcher(
    tmp_path: Path, line: FakeLine, log: DriveLog, clock: Callable[[], float], codes: object = None
) -> tuple[LogWatcher, CollectorRegistry]:
    registry = CollectorRegistry()
    dialect = DriveTarget.create("uss" if log is SINAMICS_FAULT_BUFFER else "fc", 1).dialect
    table = codes if isinstance(codes, CodeTable) else None
    w = Watched("l1", "d1", dialect, log, EVERY, table)
    store = HistoryStore(tmp_path / "history.sqlite")
    stream = EventStream(store, registry)
    found = LogWatcher({"l1": line}, stream, [w], retention=3600.0, clock=clock)
    return found, registry


def counted(registry: CollectorRegistry) -> float:
    return sum(
        s.value
        for f in registry.collect()
        for s in f.samples
        if s.name == "pkwbus_drive_events_total"
    )


async def settle(line: FakeLine, jobs: int | None = None, rounds: int = 200) -> None:
    """Until ``line`` has taken ``jobs`` jobs (or its watch has run a few times)."""
    for _ in range(rounds):
        await asyncio.sleep(EVERY / 4)
        if jobs is not None and len(line.jobs) >= jobs:
            return
    assert jobs is None, f"{len(line.jobs)} jobs, not {jobs}"


async def test_a_buffer_found_at_start_each_entry_once_with_its_runtime_time(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="pkwbus.service.history")
    buffer = FaultBuffer()
    buffer.fault(7801, 12, Runtime.of(2, 1000))  # logged while pkwbus was not running
    buffer.runtime = Runtime.of(2, 61_000)  # one minute later, by the drive's runtime
    line = FakeLine(buffer)
    codes = alarm_table("siemens-g120").decoder(947)  # type: ignore[union-attr]
    watch, registry = watcher(tmp_path, line, SINAMICS_FAULT_BUFFER, lambda: 10_000.0, codes)
    await watch.start()
    await settle(line, 1 + 3 + 64 + 3 + 1)
    await settle(line)
    (event,) = watch.store.latest()
    assert event.time == pytest.approx(10_000.0 - 60.0) and event.time_source == "runtime"
    assert event.code == "F07801" and event.value == 12 and event.drive_time == "2 d 00:00:01.000"
    assert counted(registry) == 1
    assert "drive d1 logged fault F07801" in caplog.text
    # Nothing changed since: each watch reads the counter alone.
    before = len(line.jobs)
    await settle(line)
    assert {j.request.pnu for j in line.jobs[before:]} == {944}
    await watch.stop()


async def test_a_change_of_the_counter_sweeps_and_adds_only_what_is_new(tmp_path: Path) -> None:
    buffer = FaultBuffer()
    buffer.fault(7801, 1, Runtime(1000))
    buffer.runtime = Runtime(5000)
    line = FakeLine(buffer)
    watch, registry = watcher(tmp_path, line, SINAMICS_FAULT_BUFFER, lambda: 100.0)
    await watch.start()
    await settle(line)
    buffer.acknowledge()  # the counter moves; the entry moves to the 1st acknowledged case
    buffer.fault(7802, 2, Runtime(6000))
    buffer.runtime = Runtime(7000)
    await settle(line)
    assert counted(registry) == 2
    assert [e.number for e in watch.store.latest()] == [7802, 7801]
    await watch.stop()


async def test_a_restart_repeats_nothing_and_counts_from_the_history(tmp_path: Path) -> None:
    log = AlarmLog()
    log.trip(13, 250, 7)
    line = FakeLine(log)
    first, registry = watcher(tmp_path, line, DANFOSS_ALARM_LOG, lambda: 50.0)
    await first.start()
    await settle(line)
    await first.stop()
    first.store.close()
    log.trip(14, 300, 9)  # while pkwbus is stopped
    again, registry = watcher(tmp_path, FakeLine(log), DANFOSS_ALARM_LOG, lambda: 60.0)
    await again.start()
    await settle(again.runners["l1"])  # type: ignore[arg-type]
    assert counted(registry) == 2  # the old one from the history, the new one found at start
    entries = again.store.latest()
    assert [(e.number, e.time_source) for e in entries] == [(14, "seen"), (13, "seen")]
    assert entries[0].seen == 60.0 and entries[0].drive_time == "9"
    await again.stop()


async def test_an_entry_from_before_a_power_cycle_has_no_runtime_time(tmp_path: Path) -> None:
    buffer = FaultBuffer()
    buffer.fault(7801, 1, Runtime.of(5, 0))
    buffer.runtime = Runtime(30_000)  # powered up again 30 s ago: its runtime restarted
    line = FakeLine(buffer)
    watch, _ = watcher(tmp_path, line, SINAMICS_FAULT_BUFFER, lambda: 1000.0)
    await watch.start()
    await settle(line)
    (event,) = watch.store.latest()
    assert event.time is None and event.time_source == "seen" and event.when == 1000.0
    await watch.stop()


async def test_a_drive_without_the_log_is_told_once_and_left_alone(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    line = FakeLine(lambda read: None)
    watch, _ = watcher(tmp_path, line, SINAMICS_FAULT_BUFFER, lambda: 1.0)
    await watch.start()
    await settle(line)
    assert len(line.jobs) == 1
    assert "its SINAMICS fault buffer is not watched: the drive refuses 944" in caplog.text
    await watch.stop()


async def test_a_drive_that_comes_back_is_swept_and_no_answer_is_tried_again(
    tmp_path: Path,
) -> None:
    buffer = FaultBuffer()
    line = FakeLine(buffer)
    watch, _ = watcher(tmp_path, line, SINAMICS_FAULT_BUFFER, lambda: 1.0)
    line.down = True
    await watch.start()
    await settle(line)
    assert {j.request.pnu for j in line.jobs} == {944}  # the watch, tried again
    line.down = False
    await settle(line)
    swept = len(line.jobs)
    assert any(j.request.pnu == 947 for j in line.jobs)  # the first answer: swept
    await settle(line)
    assert all(j.request.pnu == 944 for j in line.jobs[swept:])
    mark = len(line.jobs)
    watch.on_events([HealthChanged("d1", True, "answers again")])
    await settle(line, mark + 3 + 64)
    assert any(j.request.pnu == 947 for j in line.jobs[mark:])
    await watch.stop()


def newest(registry: CollectorRegistry) -> dict[tuple[str, str], float]:
    return {
        (s.labels["code"], s.labels["kind"]): s.value
        for f in registry.collect()
        for s in f.samples
        if s.name == "pkwbus_drive_event_newest_timestamp_seconds"
    }


async def test_the_newest_entry_found_is_a_gauge_from_the_start_and_over_restarts(
    tmp_path: Path,
) -> None:
    """What the alert PkwbusDriveFaultLogged reads: 0 until a first entry (so that it sees
    the first one too), the newest entry's code and when pkwbus found it after."""
    log = AlarmLog()
    line = FakeLine(log)
    clock = [100.0]
    first, registry = watcher(tmp_path, line, DANFOSS_ALARM_LOG, lambda: clock[0])
    await first.start()
    assert newest(registry) == {("", "fault"): 0.0}
    await settle(line)
    clock[0] = 200.0
    log.trip(13, 250, 7)
    await settle(line)
    assert newest(registry) == {("13", "fault"): 200.0}  # one series per drive and kind
    await first.stop()
    first.store.close()
    clock[0] = 900.0
    again, registry = watcher(tmp_path, FakeLine(log), DANFOSS_ALARM_LOG, lambda: clock[0])
    await again.start()
    await settle(again.runners["l1"])  # type: ignore[arg-type]
    assert newest(registry) == {("13", "fault"): 200.0}  # not found again: not new
    await again.stop()


async def test_the_alarm_buffer_is_read_whole_at_first_hourly_and_after_a_comeback(
    tmp_path: Path,
) -> None:
    """Between, a sweep reads its history only down to what the last one found newest."""
    buffer = AlarmBuffer(at_once=True)
    for n in range(10):
        buffer.come(7000 + n, n)
        buffer.go(0)
    line = FakeLine(buffer)
    now = [1000.0]
    dialect = DriveTarget.create("uss", 1).dialect
    w = Watched("l1", "d1", dialect, SINAMICS_ALARM_BUFFER, EVERY)
    store = HistoryStore(tmp_path / "history.sqlite")
    watch = LogWatcher({"l1": line}, EventStream(store, CollectorRegistry()), [w],
                       retention=3600.0, clock=lambda: now[0])  # fmt: skip

    def history_read(since: int) -> set[int]:
        return {j.request.subindex for j in line.jobs[since:] if j.request.pnu == 2122} - set(
            range(8)
        )

    def changes(code: int) -> int:
        mark = len(line.jobs)
        buffer.come(code, 1)
        buffer.go(0)
        return mark

    await watch.start()
    await settle(line)
    assert history_read(0) == set(range(8, 19))  # the ten, and the end
    mark = changes(7100)
    await settle(line)
    assert history_read(mark) == {8, 9}  # the new one, and the last sweep's newest
    now[0] += WHOLE_EVERY
    mark = changes(7101)
    await settle(line)
    assert history_read(mark) == set(range(8, 21))  # an hour on: whole
    mark = changes(7102)
    await settle(line)
    assert history_read(mark) == {8, 9}
    mark = len(line.jobs)
    watch.on_events([HealthChanged("d1", True, "answers again")])
    await settle(line)
    assert history_read(mark) == set(range(8, 22))  # back: whole
    assert len(store.known("d1")) == 13
    await watch.stop()
    store.close()


async def test_a_micromaster_4_seen_off_since_the_last_sweep_gives_its_new_entries_seen(
    tmp_path: Path,
) -> None:
    """Its run time counter (r2114) stands still while the drive is off and goes on from
    there (MICROMASTER 440 Parameter List 01/06, r2114): an entry from before the drive
    was off would look younger by the time it was off. Off since the last sweep (the
    counter went on less than the wall clock): what came since gets ``seen``; with the
    drive powered throughout, the counter's time."""
    buffer = Mm4Buffer(now=1000.0)
    line = FakeLine(buffer)
    now = [50_000.0]
    dialect = DriveTarget.create("uss", 1).dialect
    w = Watched("l1", "d1", dialect, MICROMASTER_FAULT_BUFFER, EVERY)
    store = HistoryStore(tmp_path / "history.sqlite")
    watch = LogWatcher({"l1": line}, EventStream(store, CollectorRegistry()), [w],
                       retention=3600.0, clock=lambda: now[0])  # fmt: skip
    await watch.start()
    buffer.fault(3, 1)  # powered throughout: the counter's time
    buffer.now += 30
    now[0] += 30
    await settle(line)
    buffer.acknowledge()
    buffer.now += 20  # then off for ten minutes: the counter stands still
    now[0] += 20 + 600
    buffer.fault(4, 2)  # after it came back, or before it went: not known
    await settle(line)
    buffer.acknowledge()
    buffer.now += 40
    now[0] += 40
    buffer.fault(5, 3)
    await settle(line)
    times = {e.number: (e.time_source, e.time) for e in store.latest()}
    assert times == {3: ("runtime", 50_000.0), 4: ("seen", None), 5: ("runtime", 50_690.0)}
    await watch.stop()
    store.close()


def test_off_is_the_counter_going_on_less_than_the_wall_clock() -> None:
    assert not was_off(None, 100.0, Runtime(5000))
    assert not was_off((0.0, Runtime(0)), 100.0, Runtime(98_500))  # a second's counter
    assert was_off((0.0, Runtime(0)), 100.0, Runtime(97_000))
    assert was_off((0.0, Runtime(90_000)), 100.0, Runtime(1000))  # SINAMICS: restarted
    assert not was_off((0.0, Runtime(0)), 86_400.0, Runtime(86_320_000))  # drift in a day
