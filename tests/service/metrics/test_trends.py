"""The values' last 15 minutes for the page's sparklines: a bounded ring per value."""

from __future__ import annotations

import math

import httpx

from pkwbus.master.reading import Reading
from pkwbus.service.metrics.trends import POINTS, Trends

KEY = ("fan1", "16-13", 0)


def reading(value: float | str, at: float) -> Reading:
    return Reading(value, None, at)


def test_each_bucket_keeps_its_last_value_oldest_first() -> None:
    trends = Trends(period=60.0)  # a point a second
    t0 = 1_000_000.0
    trends.landed(KEY, reading(1.0, t0))
    trends.landed(KEY, reading(2.0, t0 + 0.5))  # same second: the last one counts
    trends.landed(KEY, reading(3.0, t0 + 2.0))  # a second without a value between
    points = trends.points(KEY, t0 + 2.5)
    assert len(points) == POINTS
    assert points[-3:] == [2.0, None, 3.0]
    assert all(p is None for p in points[:-3])


def test_old_points_fall_out_and_time_without_values_shows_as_a_gap() -> None:
    trends = Trends(period=60.0)
    t0 = 2_000_000.0
    for i in range(100):
        trends.landed(KEY, reading(float(i), t0 + i))
    points = trends.points(KEY, t0 + 99)
    assert points == [float(i) for i in range(40, 100)]  # the last 60 s
    later = trends.points(KEY, t0 + 129)  # 30 s on, nothing landed
    assert later[:30] == [float(i) for i in range(70, 100)] and later[30:] == [None] * 30
    assert trends.points(KEY, t0 + 1000) == [None] * POINTS
    assert trends.points(("fan2", "16-13", 0), t0) == []  # never landed


def test_texts_are_no_trend_and_floats_are_kept_to_single_precision() -> None:
    trends = Trends(period=60.0)
    trends.landed(KEY, reading("FC-302", 10.0))
    assert trends.points(KEY, 10.0) == []
    trends.landed(KEY, reading(0.1, 10.0))
    (last,) = trends.points(KEY, 10.0)[-1:]
    assert last is not None and math.isclose(last, 0.1, rel_tol=1e-6)


async def test_the_api_gives_each_drives_trends() -> None:
    from pkwbus.service.http.api import create_app
    from pkwbus.sim import SimTiming, Simulator
    from tests.master.conftest import until
    from tests.service.assembly.test_service_e2e import fc_line, running, sample

    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.001), catalog="danfoss-fc")
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = """
      - name: fan1
        address: 1
        catalog: danfoss-fc
        alarms: off
        counters: off
        poll: [{parameter: "16-13", every: 50ms}]
"""
    try:
        async with running(f"lines:{fc_line('l1', server.url, drives)}") as runtime:
            await until(lambda: sample(runtime, "pkwbus_parameter_value", drive="fan1") is not None)
            app = create_app(runtime, audit=None, write_token=None)
            async with httpx.AsyncClient(
                transport=httpx.ASGITransport(app=app), base_url="http://t"
            ) as client:
                got = (await client.get("/api/v1/trends")).json()
            points = got["fan1"]["16-13"]
            assert len(points) == POINTS
            exported = sample(runtime, "pkwbus_parameter_value", drive="fan1", parameter="16-13")
            assert exported is not None and points[-1] is not None
            assert math.isclose(points[-1], exported, rel_tol=1e-3)
    finally:
        await server.close()
