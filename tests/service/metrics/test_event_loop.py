"""The service's event loop, watched: ``pkwbus_event_loop_lag_seconds`` observes how late
it ran, and a callback that held it is one log line, at most one a minute per callback."""

from __future__ import annotations

import asyncio
import logging
import time

import pytest
from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.parser import text_string_to_metric_families
from prometheus_client.utils import floatToGoString

from pkwbus.service.metrics.event_loop import (
    LAG_BUCKETS,
    LagMonitor,
    LoopWatch,
    SlowCallbacks,
    lag_histogram,
)

LAG = "pkwbus_event_loop_lag_seconds"


def buckets(registry: CollectorRegistry) -> dict[str, float]:
    """The histogram's cumulative counts by ``le``, and its ``count``."""
    found: dict[str, float] = {}
    text = generate_latest(registry).decode()
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            if sample.name == f"{LAG}_bucket":
                found[sample.labels["le"]] = sample.value
            elif sample.name == f"{LAG}_count":
                found["count"] = sample.value
    return found


async def hold(seconds: float) -> None:
    time.sleep(seconds)


async def test_a_loop_held_150_ms_is_observed_late_and_the_callback_is_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    registry = CollectorRegistry()
    watch = LoopWatch(registry, period=0.01)
    caplog.set_level(logging.WARNING, logger="pkwbus.service.loop")
    watch.start()
    try:
        await asyncio.sleep(0.05)  # the monitor woke and planned its next wake
        before = buckets(registry)
        # Its next wake is due at most 10 ms after this starts: it runs 140 ms late or more.
        await asyncio.create_task(hold(0.15), name="holder")
        await asyncio.sleep(0.05)  # the monitor's late wake ran before this one's
    finally:
        watch.stop()
    after = buckets(registry)
    assert over_100_ms(after) >= over_100_ms(before) + 1
    held = [r for r in caplog.records if r.getMessage().startswith("task 'holder' (hold) held")]
    assert len(held) == 1 and held[0].levelno == logging.WARNING
    assert float(held[0].getMessage().split(" for ")[1].split(" s")[0]) >= 0.1


def over_100_ms(counts: dict[str, float]) -> float:
    return counts["count"] - counts["0.1"]


async def test_the_monitor_stops_and_a_failing_observation_never_reaches_the_loop(
    caplog: pytest.LogCaptureFixture,
) -> None:
    loop = asyncio.get_running_loop()
    errors: list[dict[str, object]] = []
    loop.set_exception_handler(lambda _, context: errors.append(context))
    seen: list[float] = []

    def observe(lag: float) -> None:
        seen.append(lag)
        raise ValueError("a broken histogram")

    monitor = LagMonitor(observe, period=0.001)
    try:
        monitor.start(loop)
        await asyncio.sleep(0.05)
        monitor.stop()
    finally:
        loop.set_exception_handler(None)
    assert len(seen) == 1 and seen[0] >= 0.0 and errors == []  # it stopped at the failure
    assert sum("lag is not measured" in r.getMessage() for r in caplog.records) == 1
    good: list[float] = []
    monitor = LagMonitor(good.append, period=0.001)
    monitor.start(loop)
    await asyncio.sleep(0.05)
    monitor.stop()
    count = len(good)
    await asyncio.sleep(0.05)
    assert count >= 1 and len(good) == count and all(lag >= 0.0 for lag in good)


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


async def work() -> None:
    await asyncio.sleep(0)


async def test_a_callback_is_logged_at_most_once_a_minute_with_the_count_of_the_others(
    caplog: pytest.LogCaptureFixture,
) -> None:
    loop = asyncio.get_running_loop()
    clock = Clock()
    slow = SlowCallbacks(60.0, clock=clock)
    caplog.set_level(logging.WARNING, logger="pkwbus.service.loop")
    tasks = [asyncio.create_task(work(), name=f"w{i}") for i in range(3)]

    handles = [asyncio.Handle(task.get_name, (), loop) for task in tasks]  # the tasks'
    for handle in handles:  # three tasks of one coroutine function: one name
        slow(handle, 0.2)
        clock.now += 1.0
    clock.now += 60.0
    slow(handles[0], 0.3)
    await asyncio.gather(*tasks)
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        "task 'w0' (work) held the event loop for 0.200 s",
        "task 'w0' (work) held the event loop for 0.300 s; 2 more time(s) since its last"
        " line, not logged",
    ]


def test_a_flood_of_names_keeps_a_bounded_memory(caplog: pytest.LogCaptureFixture) -> None:
    loop = asyncio.new_event_loop()
    try:
        clock = Clock()
        slow = SlowCallbacks(60.0, clock=clock, limit=8)
        caplog.set_level(logging.WARNING, logger="pkwbus.service.loop")
        for i in range(100):
            callback = type(f"C{i}", (), {"__call__": lambda self: None})()
            slow(asyncio.Handle(callback, (), loop), 0.2)
        assert len(slow._last) <= 8
        assert len(caplog.records) == 100  # each a name of its own: each logged
    finally:
        loop.close()


def test_one_registry_has_one_histogram_with_buckets_from_1_ms_to_5_s() -> None:
    registry = CollectorRegistry()
    assert lag_histogram(registry) is lag_histogram(registry)
    assert LoopWatch(registry).histogram is lag_histogram(registry)
    assert LAG_BUCKETS[0] == 0.001 and LAG_BUCKETS[-1] == 5.0 and 0.1 in LAG_BUCKETS
    assert set(buckets(registry)) == {*map(floatToGoString, LAG_BUCKETS), "+Inf", "count"}
