"""A reload at the edges, in process over simulated FC drives on TCP: a drive removed or
replaced while its answer is out, maintenance across a replace and a move, a line that
cannot start, a reload once the service stops."""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest

from pkwbus.protocol.buses import decode_adr
from pkwbus.protocol.serial.telegram import Telegram
from pkwbus.service.assembly.build import Parts
from pkwbus.service.assembly.reload import Reloader, ReloadRefused
from pkwbus.service.config import parse_config
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.http.api import build_api
from pkwbus.service.http.views import line_views
from pkwbus.service.http.views.drives import DriveViews, Selection
from pkwbus.service.metrics.exposition import render
from pkwbus.service.runtime import Runtime
from pkwbus.service.writes.checks import ApiError
from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.serving.ends import TcpEnd
from tests.service.assembly.test_reload_dp import reloadable, until


def drive(name: str, address: int, every: str = "100ms", **extra: Any) -> dict[str, Any]:
    poll = [{"parameter": "16-13", "every": every}]
    return {"name": name, "address": address, "catalog": "danfoss-fc", "poll": poll, **extra}


def line(name: str, url: str, drives: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "name": name, "port": url, "protocol": "fc", "baudrate": 115200, "timeout": "500ms",
        "retries": 0, "alarms": "off", "settings": "off", "events": "off", "counters": "off",
        "drives": drives,
    }  # fmt: skip


@dataclass
class Lines:
    ends: list[TcpEnd]
    heard: list[tuple[float, int, int]]  # (loop time, simulator, address) of each request
    runtime: Runtime
    parts: Parts
    reloader: Reloader
    text: list[str] = field(default_factory=list)

    def set(self, lines: list[dict[str, Any]]) -> None:
        self.text[0] = json.dumps({"audit_db": ":memory:", "lines": lines})

    async def metrics(self) -> str:
        return (await render(self.parts.registry)).decode()

    def to(self, sim: int, address: int, since: float) -> int:
        return sum(1 for t, s, a in self.heard if s == sim and a == address and t >= since)


@asynccontextmanager
async def running(
    addresses: list[list[int]], lines: Callable[[list[str]], list[dict[str, Any]]], delay: float
) -> AsyncIterator[Lines]:
    loop = asyncio.get_running_loop()
    heard: list[tuple[float, int, int]] = []
    async with AsyncExitStack() as stack:
        ends = []
        for n, found in enumerate(addresses):
            sim = Simulator("fc", found, timing=SimTiming(response_delay=delay), seed=2,
                            catalog="danfoss-fc")  # fmt: skip
            answer = sim.answer

            def hear(t: Telegram, now: float | None = None, n: int = n, sim: Any = sim,
                     answer: Any = answer) -> Any:  # fmt: skip
                heard.append((loop.time(), n, decode_adr(sim.protocol, t.adr).address))
                return answer(t, now)

            sim.answer = hear  # type: ignore[method-assign,assignment]
            end = await sim.serve_tcp("127.0.0.1", 0)
            stack.push_async_callback(end.close)
            ends.append(end)
        text = [json.dumps({"audit_db": ":memory:", "lines": lines([e.url for e in ends])})]
        config, runtime, parts, reloader = await reloadable(text, stack)
        found_lines = Lines(ends, heard, runtime, parts, reloader, text)
        polled = [d.name for _, d in config.drives() if not d.maintenance]
        await until(lambda: all(
            any(k[0] == n for k in runtime.snapshot.readings) for n in polled))  # fmt: skip
        yield found_lines


def busy(lines: Lines, line_name: str, name: str) -> Callable[[], bool]:
    planner = lines.runtime.runners[line_name].planner  # type: ignore[attr-defined]
    return lambda: bool(planner.drive(name).busy)


async def test_a_drive_removed_with_its_answer_out_leaves_the_line_going(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Its answer comes after the reload took it away: counted as the line's time only;
    the line goes on (no reopen), nothing of the drive is exported."""
    async with running([[1, 2]], lambda u: [line("l", u[0], [drive("d1", 1), drive("d2", 2)])],
                       0.15) as lines:  # fmt: skip
        lines.set([line("l", lines.ends[0].url, [drive("d1", 1)])])
        await until(busy(lines, "l", "d2"))
        outcome = await lines.reloader.reload()
        assert outcome.changes == ["line l: drive d2 removed"]
        loop = asyncio.get_running_loop()
        after = loop.time()
        await until(lambda: lines.to(0, 1, after) >= 5)
        assert lines.ends[0].connections == 1
        assert "unexpected error" not in caplog.text and "recording failed" not in caplog.text
        text = await lines.metrics()
        assert 'drive="d2"' not in text
        assert lines.to(0, 2, after + 0.2) == 0


async def test_a_replaced_drive_never_shows_the_old_drives_value() -> None:
    """d2 moves to an address nobody answers: the answer of the old address that was out
    at the reload is not d2's value."""
    async with running([[1, 2]], lambda u: [line("l", u[0], [drive("d1", 1), drive("d2", 2)])],
                       0.15) as lines:  # fmt: skip
        lines.set([line("l", lines.ends[0].url, [drive("d1", 1), drive("d2", 4)])])
        await until(busy(lines, "l", "d2"))
        outcome = await lines.reloader.reload()
        assert outcome.changes == ["line l: drive d2 replaced"]
        seen: list[object] = []
        for _ in range(100):
            seen.append(lines.runtime.snapshot.readings.get(("d2", "16-13", 0)))
            await asyncio.sleep(0.01)
        assert seen == [None] * 100


async def test_maintenance_stays_across_a_change_in_place_and_a_move() -> None:
    """``maintenance: true`` kept while the drive's writable list changes; a maintenance the
    API began follows the drive to another line."""

    def first(u: list[str]) -> list[dict[str, Any]]:
        return [
            line("a", u[0], [drive("d1", 1), drive("d2", 2, maintenance=True)]),
            line("b", u[1], [drive("e1", 1), drive("e2", 2)]),
        ]

    async with running([[1, 2], [1, 2, 3]], first, 0.002) as lines:
        api = build_api(lines.runtime, write_token="t0ken")  # no audit log: none kept
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=api.app),
                                     base_url="http://pkwbus.test") as client:  # fmt: skip
            r = await client.put("/api/v1/drives/e2/maintenance",
                                 json={"on": True, "reason": "fitter"},
                                 headers={"Authorization": "Bearer t0ken"})  # fmt: skip
        assert r.status_code == 200, r.text
        a, b = lines.ends[0].url, lines.ends[1].url
        lines.set([
            line("a", a, [drive("d1", 1), drive("d2", 2, maintenance=True, writable=["3-41"]),
                          drive("e2", 3)]),
            line("b", b, [drive("e1", 1)]),
        ])  # fmt: skip
        outcome = await lines.reloader.reload()
        assert "line b: drive e2 removed" in outcome.changes
        assert "line a: drive e2 added" in outcome.changes
        held = lines.runtime.snapshot.maintenance
        assert held["d2"].reason == "configuration" and held["e2"].reason == "fitter"
        since = asyncio.get_running_loop().time()
        await asyncio.sleep(1.0)
        assert lines.to(0, 2, since) == 0 and lines.to(0, 3, since) == 0
        assert lines.to(0, 1, since) > 0


async def test_a_line_that_cannot_start_is_shown_down_and_started_by_the_next_reload(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    async with running([[1], [1]], lambda u: [line("a", u[0], [drive("d1", 1)])],
                       0.002) as lines:  # fmt: skip
        lines.set([line("a", lines.ends[0].url, [drive("d1", 1)]),
                   line("b", lines.ends[1].url, [drive("e1", 1)])])  # fmt: skip
        build = Parts.build

        async def broken(self: Parts, plan: Any) -> Any:
            raise OSError("no such device")

        monkeypatch.setattr(Parts, "build", broken)
        with caplog.at_level(logging.ERROR):
            outcome = await lines.reloader.reload()
        assert outcome.loaded and outcome.outcome == "partial"
        assert outcome.problems == ["line b added but cannot start: no such device"]
        text = await lines.metrics()
        assert "pkwbus_config_last_reload_successful 0.0" in text
        assert 'pkwbus_line_up{line="b"} 0.0' in text
        assert 'pkwbus_drive_up{drive="e1",line="b"} 0.0' in text
        # The API shows it too: down, with its drive, and asked for by name.
        shown = {v.name: (v.open, v.drives) for v in line_views(lines.runtime, {}, time.time())}
        assert shown == {"a": (True, 1), "b": (False, 1)}
        views = DriveViews(lines.runtime)
        assert views.select(Selection(line="b"))[0] == ["e1"]
        with pytest.raises(ApiError) as unknown:
            views.select(Selection(line="c"))
        assert unknown.value.status == 404
        monkeypatch.setattr(Parts, "build", build)
        outcome = await lines.reloader.reload()  # the same file: the line starts now
        assert outcome.outcome == "ok" and outcome.changes == ["line b started"]
        await until(lambda: ("e1", "16-13", 0) in lines.runtime.snapshot.readings)
        assert "pkwbus_config_last_reload_successful 1.0" in await lines.metrics()


async def test_no_reload_once_the_service_stops(tmp_path: Path) -> None:
    async with running([[1]], lambda u: [line("a", u[0], [drive("d1", 1)])], 0.002) as lines:
        await lines.reloader.close()
        with pytest.raises(ReloadRefused):
            await lines.reloader.reload()


async def test_a_settings_change_stays_flagged_and_told_once_across_a_reload(
    tmp_path: Path,
) -> None:
    """What the settings watcher knows lives in the history database: a reload that makes
    the watchers again keeps a flagged change flagged, does not tell it again, and counts
    the drive's events as before."""
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.002), seed=2,
                    catalog="danfoss-fc")  # fmt: skip
    end = await sim.serve_tcp("127.0.0.1", 0)
    swept = {"every": "1s", "parameters": ["3-41"]}

    def text(polls: list[str]) -> str:
        d1 = {"name": "d1", "address": 1, "catalog": "danfoss-fc",
              "poll": [{"parameter": p, "every": "200ms"} for p in polls]}  # fmt: skip
        found = line("a", end.url, [d1])
        found["settings"] = swept
        return json.dumps({"audit_db": str(tmp_path / "audit.sqlite"), "lines": [found]})

    file = [text(["16-13"])]
    stack = AsyncExitStack()
    store = HistoryStore(parse_config(file[0], environ={}).history_path)
    _, _, parts, reloader = await reloadable(file, stack, store)
    flag = 'pkwbus_drive_setting_changed{drive="d1",index="0",line="a",parameter="3-41"} 1.0'
    told = 'kind="setting"'

    async def metrics() -> str:
        return (await render(parts.registry)).decode()

    async def shown(wanted: str) -> str:
        latest = [""]

        async def look() -> bool:
            latest[0] = await metrics()
            return wanted in latest[0]

        loop = asyncio.get_running_loop()
        deadline = loop.time() + 30
        while not await look():
            assert loop.time() < deadline, latest[0]
            await asyncio.sleep(0.1)
        return latest[0]

    def events(text: str) -> list[str]:
        return [s for s in text.splitlines() if s.startswith("pkwbus_drive_events_total") and
                told in s]  # fmt: skip

    try:
        await shown('pkwbus_drive_settings_swept_timestamp_seconds{drive="d1",line="a"}')
        sim.keypad(1, 341, 777)  # 3-41 ramp up time, set at the drive
        before = events(await shown(flag))
        assert len(before) == 1 and before[0].endswith(" 1.0")
        file[0] = text(["16-13", "16-14"])
        outcome = await reloader.reload()
        assert outcome.changes == ["line a: drive d1: polls changed"]
        after = await shown(
            'pkwbus_parameter_value{drive="d1",index="0",line="a",parameter="16-14"}'
        )
        assert flag in after and events(after) == before
        await asyncio.sleep(2.5)  # two sweeps of the new watcher
        later = await metrics()
        assert flag in later and events(later) == before
    finally:
        await stack.aclose()
        store.close()
        await end.close()


async def test_a_drive_whose_sweep_a_reload_turns_off_shows_no_sweep_any_more(
    tmp_path: Path,
) -> None:
    """A reload that turns a drive's settings sweep off: the read model drops what it showed
    of the last sweep; the other drive, still swept, keeps its own. Then one that turns
    every drive's off: nothing of a sweep is shown, nor kept to be asked for."""
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.002), seed=2,
                    catalog="danfoss-fc")  # fmt: skip
    end = await sim.serve_tcp("127.0.0.1", 0)
    swept = {"every": "1s", "parameters": ["3-41"]}

    def text(d1_swept: bool, d2_swept: bool = True) -> str:
        d1, d2 = drive("d1", 1, "200ms"), drive("d2", 2, "200ms")
        d1["settings"] = swept if d1_swept else "off"
        d2["settings"] = swept if d2_swept else "off"
        return json.dumps({"audit_db": str(tmp_path / "audit.sqlite"),
                           "lines": [line("a", end.url, [d1, d2])]})  # fmt: skip

    file = [text(True)]
    stack = AsyncExitStack()
    store = HistoryStore(parse_config(file[0], environ={}).history_path)
    _, runtime, _, reloader = await reloadable(file, stack, store)
    try:
        shown = runtime.snapshot.settings
        await until(lambda: {"d1", "d2"} <= shown.keys())
        file[0] = text(False)
        outcome = await reloader.reload()
        assert outcome.loaded and not outcome.problems, outcome
        await until(lambda: "d1" not in runtime.snapshot.settings)
        assert "d2" in runtime.snapshot.settings
        assert runtime.settings is not None
        # Every drive's sweep off: no watcher is left to answer for their settings either.
        file[0] = text(False, False)
        outcome = await reloader.reload()
        assert outcome.loaded and not outcome.problems, outcome
        await until(lambda: not runtime.snapshot.settings)
        assert runtime.settings is None
    finally:
        await stack.aclose()
        store.close()
        await end.close()
