"""What the views show after a reload that changes a drive in place, in process over
simulated FC drives on TCP: a value never in a format it was not decoded in, the info
series as the configuration gives it now, a parameter described again not waiting for
good, a change of the writable list or limits said and marked, a replaced drive without
the old one's errors."""

from __future__ import annotations

import asyncio
import json
import time
from contextlib import AsyncExitStack
from typing import Any

import pytest

from pkwbus.protocol.values import ParameterRef
from pkwbus.service.http.views.drives import DriveViews, Selection, overview_row
from pkwbus.service.metrics.exposition import render
from pkwbus.service.writes.checks import described_format
from pkwbus.service.writes.reads import Reads
from pkwbus.sim import SimTiming, Simulator
from tests.service.assembly.test_reload_dp import reloadable, until
from tests.service.assembly.test_reload_edges import drive, line, running

KEY = ("d1", "16-13", 0)


def scaled(scale: float, unit: str, **extra: Any) -> dict[str, Any]:
    found = drive("d1", 1, **extra)
    found["poll"] = [{"parameter": "16-13", "every": "100ms", "scale": scale, "unit": unit}]
    return found


async def test_a_value_decoded_otherwise_now_is_not_shown_until_the_drive_answers() -> None:
    """The drive in maintenance keeps its last reading; a reload changes the poll's scale and
    unit: its raw 400 read at 0.1 Hz is not shown as 40 rpm (API, /metrics, trend); taken
    out of maintenance, it shows what the drive answers, decoded the new way."""
    async with running([[1, 2]], lambda u: [line("l", u[0], [scaled(0.1, "Hz"), drive("d2", 2)])],
                       0.002) as lines:  # fmt: skip
        url, views, trends = lines.ends[0].url, DriveViews(lines.runtime), lines.parts.trends
        value = 'pkwbus_parameter_value{drive="d1",index="0",line="l",parameter="16-13"}'
        lines.set([line("l", url, [scaled(0.1, "Hz", maintenance=True), drive("d2", 2)])])
        await lines.reloader.reload()
        assert [v["unit"] for v in json.loads(await views.full(["d1"]))[0]["values"]] == ["Hz"]
        assert value in await lines.metrics()
        assert any(p is not None for p in trends.points(KEY, time.time()))
        lines.set([line("l", url, [scaled(6.0, "rpm", maintenance=True), drive("d2", 2)])])
        assert (await lines.reloader.reload()).changes == ["line l: drive d1: polls changed"]
        await asyncio.sleep(0.3)
        assert json.loads(await views.full(["d1"]))[0]["values"] == []
        assert value not in await lines.metrics()
        assert trends.points(KEY, time.time()) == []
        lines.set([line("l", url, [scaled(6.0, "rpm"), drive("d2", 2)])])
        await lines.reloader.reload()
        await until(lambda: KEY in lines.runtime.snapshot.readings)
        shown = json.loads(await views.full(["d1"]))[0]["values"][0]
        assert shown["unit"] == "rpm" and shown["value"] == pytest.approx(shown["raw"] * 6.0)


@pytest.mark.parametrize("describe", ["off", "auto"])
async def test_a_changed_override_of_a_polled_parameter_reaches_its_info_series(
    describe: str,
) -> None:
    a, b = drive("d1", 1, describe=describe), drive("d1", 1, describe=describe)
    a["poll"] = [{"parameter": "16-13", "every": "100ms", "name": "Fan speed", "unit": "Hz"}]
    b["poll"] = [{"parameter": "16-13", "every": "100ms", "name": "Belt speed", "unit": "rpm",
                  "scale": 6}]  # fmt: skip

    def info(text: str) -> list[str]:
        return [s for s in text.splitlines() if s.startswith("pkwbus_parameter_info{")]

    async with running([[1]], lambda u: [line("l", u[0], [a])], 0.002) as lines:
        await until(lambda: not lines.runtime.snapshot.decoding["d1"].pending)
        assert 'name="Fan speed"' in info(await lines.metrics())[0]
        lines.set([line("l", lines.ends[0].url, [b])])
        await lines.reloader.reload()
        await until(lambda: KEY in lines.runtime.snapshot.readings)
        found = info(await lines.metrics())
        assert len(found) == 1
        assert 'name="Belt speed"' in found[0] and 'unit="rpm"' in found[0]
        assert 'source="config"' in found[0]  # its scale is the configuration's


async def test_a_parameter_given_back_by_a_reload_is_not_left_waiting_for_good() -> None:
    """Reload 1 takes poll 16-14 and writable 3-41 away, reload 2 gives them back: the
    drive's describer has them still, nothing settles them again; the API reads and writes
    them at once, as before."""

    def d(polls: list[str], writable: list[str]) -> dict[str, Any]:
        found = drive("d1", 1, writable=writable)
        found["poll"] = [{"parameter": p, "every": "100ms"} for p in polls]
        return found

    async with running([[1]], lambda u: [line("l", u[0], [d(["16-13", "16-14"], ["3-41"])])],
                       0.002) as lines:  # fmt: skip
        decoding = lines.runtime.snapshot.decoding["d1"]
        await until(lambda: not decoding.pending)
        lines.set([line("l", lines.ends[0].url, [d(["16-13"], [])])])
        await lines.reloader.reload()
        lines.set([line("l", lines.ends[0].url, [d(["16-13", "16-14"], ["3-41"])])])
        await lines.reloader.reload()
        decoding = lines.runtime.snapshot.decoding["d1"]
        assert decoding.pending == set()
        await until(lambda: ("d1", "16-14", 0) in lines.runtime.snapshot.readings)
        entry = lines.runtime.drives["d1"]
        for ref in (ParameterRef(341, None, "3-41"), ParameterRef(1614, None, "16-14")):
            described_format(lines.runtime, entry, ref)  # no 503 not_described


@pytest.mark.parametrize(
    ("before", "after", "said"),
    [
        ({"writable": ["3-42"]}, {"writable": ["3-41", "3-42"]}, "writable parameters changed"),
        ({"writable": ["3-42"], "parameters": {"3-42": {"max": 100}}},
         {"writable": ["3-42"], "parameters": {"3-42": {"max": 50}}},
         "parameter overrides changed"),
    ],
)  # fmt: skip
async def test_a_change_of_the_writable_list_or_limits_alone_is_said_and_marks_the_drive(
    before: dict[str, Any], after: dict[str, Any], said: str
) -> None:
    """The drive in maintenance: no value of it lands to mark it changed."""
    one = drive("d1", 1, describe="off", maintenance=True, **before)
    async with running([[1, 2]], lambda u: [line("l", u[0], [one, drive("d2", 2)])],
                       0.002) as lines:  # fmt: skip
        views = DriveViews(lines.runtime)
        names, token = views.select(Selection(drive="d1"))
        was = json.loads(await views.full(names))[0]["writable"]
        two = drive("d1", 1, describe="off", maintenance=True, **after)
        lines.set([line("l", lines.ends[0].url, [two, drive("d2", 2)])])
        outcome = await lines.reloader.reload()
        assert outcome.changes == [f"line l: drive d1: {said}"]
        assert views.select(Selection(drive="d1", changed_since=token))[0] == ["d1"]
        assert json.loads(await views.full(["d1"]))[0]["writable"] != was


async def test_a_change_of_a_drives_default_on_its_line_is_said_and_marks_its_drives() -> None:
    in_maintenance = drive("d1", 1, describe="off", maintenance=True)
    async with running([[1, 2]], lambda u: [line("l", u[0], [in_maintenance, drive("d2", 2)])],
                       0.002) as lines:  # fmt: skip
        views = DriveViews(lines.runtime)
        _, token = views.select(Selection(drive="d1"))
        changed = line("l", lines.ends[0].url, [in_maintenance, drive("d2", 2)])
        changed["events_every"] = "30s"
        lines.set([changed])
        assert (await lines.reloader.reload()).changes == ["line l: events_every changed"]
        assert views.select(Selection(drive="d1", changed_since=token))[0] == ["d1"]


async def test_a_replaced_drive_does_not_inherit_the_old_ones_timeout() -> None:
    """d2 moves from an address nobody answers to one that answers while the old address's
    exchange is out: its timeout is the line's time alone."""
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.002), seed=2,
                    catalog="danfoss-fc")  # fmt: skip
    async with AsyncExitStack() as stack:
        end = await sim.serve_tcp("127.0.0.1", 0)
        stack.push_async_callback(end.close)

        def text(address: int) -> str:
            found = line("l", end.url, [drive("d1", 1), drive("d2", address)])
            return json.dumps({"audit_db": ":memory:", "lines": [found]})

        file = [text(5)]
        _, runtime, parts, reloader = await reloadable(file, stack)
        planner = runtime.runners["l"].planner  # type: ignore[attr-defined]
        await until(lambda: not runtime.snapshot.drives["d2"].up)
        await until(lambda: bool(planner.drive("d2").busy))
        telegrams = runtime.snapshot.totals["l"].telegrams
        file[0] = text(2)
        assert (await reloader.reload()).changes == ["line l: drive d2 replaced"]
        await until(lambda: ("d2", "16-13", 0) in runtime.snapshot.readings)
        assert runtime.snapshot.totals["l"].telegrams > telegrams  # the line's time goes on
        assert overview_row(runtime, "d2", time.time()).telegram_errors == 0
        errors = 'pkwbus_telegram_errors_total{drive="d2",'  # a series once one is counted
        assert errors not in (await render(parts.registry)).decode()


@pytest.mark.parametrize(
    ("override", "kept"), [({"scale": 0.1}, False), ({"unit": "min"}, False), ({"max": 50}, True)]
)
async def test_a_latest_value_decoded_otherwise_now_is_not_shown_until_read_again(
    override: dict[str, Any], kept: bool
) -> None:
    """3-41, writable and polled by nothing: read on demand, its value is the one the drive's
    writable parameters show (and a write's old value). A reload changes its overrides, the
    drive in maintenance (nothing of it is answered): a value decoded otherwise now is no
    longer shown; one decoded the same way (a limit changed) stays; read again, it is
    decoded as the configuration says now."""

    def d1(**extra: Any) -> dict[str, Any]:
        given = {"parameters": {"3-41": {"scale": 0.01, **override}}} if extra else {}
        return drive("d1", 1, describe="off", writable=["3-41"], **given, **extra)

    key = ("d1", 341, 0)
    async with running([[1, 2]], lambda u: [line("l", u[0], [d1(), drive("d2", 2)])],
                       0.002) as lines:  # fmt: skip
        runtime, url, views = lines.runtime, lines.ends[0].url, DriveViews(lines.runtime)

        async def shown() -> Any:
            (found,) = [w for w in json.loads(await views.full(["d1"]))[0]["writable"]
                        if w["parameter"] == "3-41"]  # fmt: skip
            return found["value"], found["unit"]

        await Reads(runtime).read("d1", "3-41", None)
        raw = runtime.snapshot.latest[key].raw
        assert await shown() == (pytest.approx(raw * 0.01), "s")  # the catalog's: 0.01 s
        lines.set([line("l", url, [d1(maintenance=True), drive("d2", 2)])])
        await lines.reloader.reload()
        value, unit = await shown()
        if kept:
            assert (value, unit) == (pytest.approx(raw * 0.01), "s")
            return
        assert key not in runtime.snapshot.latest and value is None
        lines.set([line("l", url, [d1(maintenance=False), drive("d2", 2)])])
        await lines.reloader.reload()
        await Reads(runtime).read("d1", "3-41", None)
        raw = runtime.snapshot.latest[key].raw
        scale = override.get("scale", 0.01)
        assert await shown() == (pytest.approx(raw * scale), override.get("unit", "s"))
