"""A service in hot standby (fake engine, simulated FC drives on TCP, in process): a line's
port opens only while this instance holds the line, closes at once when it is lost, and a
line held again starts afresh; its series and the API follow who masters it."""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from types import SimpleNamespace
from typing import Any

import pytest
from prometheus_client.parser import text_string_to_metric_families

from pkwbus.link.serialport import closer
from pkwbus.service.assembly import standby_lines
from pkwbus.service.metrics.exposition import render
from tests.service.standby_service.fakes import (
    AUTH,
    Master,
    Service,
    config_text,
    service,
    single,
    until,
)


def series(text: str, name: str) -> dict[tuple[tuple[str, str], ...], float]:
    return {
        tuple(sorted(s.labels.items())): s.value
        for f in text_string_to_metric_families(text)
        for s in f.samples
        if s.name == name
    }


def polled(svc: Service, drives: tuple[str, ...]) -> bool:
    readings = svc.runtime.snapshot.readings
    return all(any(k[0] == d for k in readings) for d in drives)


async def test_a_line_runs_only_while_held_and_stops_at_once_when_lost() -> None:
    async with service() as svc:
        assert svc.engine.started and svc.engine.calls == ["start"]
        await asyncio.sleep(0.3)  # time enough for a port to open, were any started
        assert svc.ends["l1"].connections == svc.ends["l2"].connections == 0
        assert not svc.heard and not svc.runtime.runners
        assert not svc.runtime.snapshot.lines and not svc.runtime.drives

        svc.engine.grant("l1")
        await until(lambda: polled(svc, ("a1", "a2")))
        assert svc.open_connections("l1") == 1
        assert svc.ends["l2"].connections == 0 and svc.requests("l2") == 0
        assert svc.runtime.snapshot.lines == {"l1": True}

        svc.engine.lose("l1", Master("there", "http://there.example:9725"))
        await until(lambda: svc.open_connections("l1") == 0 and "l1" not in svc.runtime.runners)
        after = time.monotonic()
        await asyncio.sleep(0.3)
        assert svc.requests("l1", after) == 0  # silent once stopped
        snap = svc.runtime.snapshot
        assert "l1" not in snap.lines and not {"a1", "a2"} & set(snap.drives)
        assert not any(k[0] in ("a1", "a2") for k in snap.readings)
        assert not svc.runtime.drives

        svc.engine.grant("l1")  # held again: a fresh runner, a fresh connection
        await until(lambda: polled(svc, ("a1", "a2")) and svc.requests("l1", after) > 0)
        assert svc.ends["l1"].connections == 2 and svc.open_connections("l1") == 1


async def test_a_closed_fence_keeps_the_line_silent_before_the_engine_says_so() -> None:
    """A renewal that stopped: the fence closes, nothing goes out, although no
    on_change(False) came yet; the port is given up."""
    async with service() as svc:
        svc.engine.grant("l1")
        await until(lambda: polled(svc, ("a1", "a2")))
        svc.engine.expire("l1")
        closed = time.monotonic()
        await until(lambda: svc.open_connections("l1") == 0)
        await asyncio.sleep(0.5)
        assert svc.requests("l1", closed + 0.05) == 0
        assert svc.runtime.snapshot.lines.get("l1") is False
        svc.engine.lose("l1")
        await until(lambda: "l1" not in svc.runtime.runners)


async def test_metrics_say_who_masters_and_a_line_mastered_elsewhere_has_no_series() -> None:
    async with service() as svc:
        svc.engine.grant("l1")
        svc.engine.masters["l2"] = Master("there", "http://there.example:9725")
        await until(lambda: polled(svc, ("a1", "a2")))
        text = await svc.metrics()
        assert series(text, "pkwbus_line_master") == {
            (("line", "l1"),): 1.0, (("line", "l2"),): 0.0,
        }  # fmt: skip
        assert series(text, "pkwbus_standby_etcd_up") == {(): 1.0}
        assert series(text, "pkwbus_standby_takeovers_total") == {
            (("line", "l1"),): 1.0, (("line", "l2"),): 0.0,
        }  # fmt: skip
        assert 'line="l1"' in text.replace('pkwbus_line_master{line="l1"}', "")
        assert 'drive="a1"' in text
        others = [x for x in text.splitlines() if 'line="l2"' in x or 'drive="b1"' in x]
        assert all(x.startswith(("pkwbus_line_master", "pkwbus_standby_")) for x in others)

        svc.engine.lose("l1", Master("there", None))
        await until(lambda: "l1" not in svc.runtime.runners)
        text = await svc.metrics()
        assert series(text, "pkwbus_line_master")[(("line", "l1"),)] == 0.0
        left = [x for x in text.splitlines() if ('line="l1"' in x or 'drive="a1"' in x)]
        assert left and all(x.startswith(("pkwbus_line_master", "pkwbus_standby_")) for x in left)
        svc.engine.etcd_up = False
        assert series(await svc.metrics(), "pkwbus_standby_etcd_up") == {(): 0.0}


async def test_a_drive_mastered_elsewhere_answers_409_not_master() -> None:
    async with service() as svc:
        svc.engine.grant("l1")
        svc.engine.masters["l2"] = Master("there", "http://there.example:9725")
        await until(lambda: polled(svc, ("a1", "a2")))
        client = svc.client
        want = {"kind": "not_master", "master": "there", "url": "http://there.example:9725"}
        for method, path, body in (
            ("GET", "/api/v1/drives/b1/parameters/16-13", None),
            ("PUT", "/api/v1/drives/b1/parameters/3-41", {"value": 1}),
            ("PUT", "/api/v1/drives/b1/maintenance", {"on": True, "reason": "x"}),
            ("GET", "/api/v1/drives/b1/settings", None),
            ("GET", "/api/v1/drives?drive=b1", None),
            ("GET", "/api/v1/drives?line=l2", None),
            ("GET", "/api/v1/events?drive=b1", None),
            ("GET", "/api/v1/trends?drive=b1", None),
        ):
            r = await client.request(method, path, json=body, headers=AUTH)
            assert r.status_code == 409, (path, r.text)
            error = r.json()["error"]
            assert {k: error[k] for k in want} == want, (path, error)
            assert "l2" in error["message"] and "there" in error["message"]
        before = svc.requests("l2")
        assert before == 0  # nothing went out on a line not held
        # Nobody masters l2: null master and URL.
        svc.engine.masters.pop("l2")
        r = await client.get("/api/v1/drives/b1/parameters/16-13")
        assert r.status_code == 409
        assert r.json()["error"]["master"] is None and r.json()["error"]["url"] is None
        # A drive held here is read; an unknown one is still 404.
        r = await client.get("/api/v1/drives/a1/parameters/16-13")
        assert r.status_code == 200, r.text
        r = await client.get("/api/v1/drives/zz/parameters/16-13")
        assert r.status_code == 404 and r.json()["error"]["kind"] == "unknown_drive"
        for path, kind in (
            ("/api/v1/drives?drive=zz", "unknown_drive"),
            ("/api/v1/drives?line=zz", "unknown_line"),
            ("/api/v1/events?drive=zz", "unknown_drive"),
            ("/api/v1/trends?drive=zz", "unknown_drive"),
        ):
            r = await client.get(path)
            assert r.status_code == 404 and r.json()["error"]["kind"] == kind, (path, r.text)
        r = await client.get("/api/v1/drives?drive=a1")
        assert r.status_code == 200 and [d["name"] for d in r.json()] == ["a1"], r.text


async def test_a_standby_is_ready_with_the_lines_it_masters_up() -> None:
    """An instance that masters nothing stands by, ready (a rolling update waits for it);
    one whose line is down is not."""
    async with service() as svc:
        r = await svc.client.get("/readyz")
        assert r.status_code == 200 and r.json()["lines"] == {}, r.text
        svc.engine.grant("l1")
        await until(lambda: polled(svc, ("a1", "a2")))
        r = await svc.client.get("/readyz")
        assert r.status_code == 200 and r.json()["lines"] == {"l1": True}
        svc.engine.expire("l1")  # its port given up
        await until(lambda: svc.runtime.snapshot.lines.get("l1") is False)
        r = await svc.client.get("/readyz")
        assert r.status_code == 503 and r.json()["lines"] == {"l1": False}


async def test_lines_name_their_master() -> None:
    async with service() as svc:
        svc.engine.grant("l1")
        svc.engine.masters["l2"] = Master("there", "http://there.example:9725")
        await until(lambda: polled(svc, ("a1", "a2")))
        r = await svc.client.get("/api/v1/lines")
        assert r.status_code == 200
        lines = {x["name"]: x for x in r.json()}
        assert list(lines) == ["l1", "l2"]
        assert lines["l1"]["master"] == {"name": "here", "url": "http://here.example:9725",
                                         "here": True}  # fmt: skip
        assert lines["l1"]["open"] is True and lines["l1"]["drives"] == 2
        assert lines["l2"]["master"] == {"name": "there", "url": "http://there.example:9725",
                                         "here": False}  # fmt: skip
        assert lines["l2"]["open"] is False and lines["l2"]["drives"] == 1
        assert lines["l2"]["drives_up"] == 0
        svc.engine.masters.pop("l2")
        r = await svc.client.get("/api/v1/lines")
        assert {x["name"]: x["master"] for x in r.json()}["l2"] is None


async def test_a_maintenance_switch_whose_line_is_lost_meanwhile_answers_409_not_master() -> None:
    """The line is lost while the switch's audit row is stored: nothing is switched here (its
    new master keeps the drive), 409 names where to go, and the row says nothing was sent."""
    async with service() as svc:
        svc.engine.grant("l1")
        await until(lambda: polled(svc, ("a1", "a2")))
        writer = svc.api.audit_writer
        attempt, outcome = writer.attempt, writer.outcome
        outcomes: list[str] = []

        async def attempted(entry: Any) -> Any:
            row = await attempt(entry)
            svc.engine.lose("l1", Master("there", "http://there.example:9725"))
            await until(lambda: "l1" not in svc.runtime.runners)
            return row

        async def completed(row: Any, **kw: Any) -> Any:
            outcomes.append(kw["outcome"])
            return await outcome(row, **kw)

        writer.attempt, writer.outcome = attempted, completed
        r = await svc.client.put(
            "/api/v1/drives/a1/maintenance", json={"on": True, "reason": "bearing"}, headers=AUTH
        )
        assert r.status_code == 409, r.text
        error = r.json()["error"]
        assert (error["kind"], error["master"]) == ("not_master", "there")
        assert outcomes == ["not_sent"]
        assert "a1" not in svc.runtime.api_maintenance
        assert "a1" not in svc.runtime.snapshot.maintenance


async def test_the_ports_close_before_the_leases_are_revoked() -> None:
    seen: list[dict[str, bool]] = []
    async with service() as svc:
        svc.engine.grant("l1")
        svc.engine.grant("l2")
        await until(lambda: polled(svc, ("a1", "a2", "b1")))

        runners = dict(svc.runtime.runners)
        assert all(r.link.is_open for r in runners.values())  # type: ignore[attr-defined]

        def at_stop() -> None:  # each line's port, open or not, when the leases go
            seen.append({n: r.link.is_open for n, r in runners.items()})  # type: ignore[attr-defined]
            # and its connection as the gateway sees it (the socket's close runs in a thread)
            seen.append({n: svc.open_connections(n) > 0 for n in runners})

        svc.engine.at_stop = at_stop
        await svc.runtime.stop()
        assert svc.engine.calls == ["start", "stop"] and svc.engine.revoked_lines
        svc.engine.grant("l1")  # a win that comes once stopped starts nothing
        await asyncio.sleep(0.3)
        await until(lambda: svc.open_connections("l1") == svc.open_connections("l2") == 0)
        assert svc.ends["l1"].connections == 1
    # Both lines' ports were closed when the leases were revoked, their connections too.
    assert seen == [{"l1": False, "l2": False}] * 2


async def test_a_port_whose_close_does_not_end_leaves_the_lines_lease_to_expire(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A close that hangs (an adapter's output that does not drain): the lines' lease is not
    revoked, so the standby takes the lines only once it expired, and it is said."""
    monkeypatch.setattr(standby_lines, "PORTS_CLOSED_WAIT", 0.2)
    jammed = threading.Event()
    async with service() as svc:
        svc.engine.grant("l1")
        await until(lambda: polled(svc, ("a1", "a2")))
        closer.wrap(stuck := SimpleNamespace(close=lambda: jammed.wait(10)), "jammed")
        stuck.close()  # handed to the closer's thread, ahead of the line's port
        try:
            with caplog.at_level(logging.WARNING, "pkwbus.service.standby"):
                await svc.runtime.stop()
        finally:
            jammed.set()
        assert svc.engine.calls == ["start", "stop"] and not svc.engine.revoked_lines
    assert any("left to expire" in r.message for r in caplog.records)


async def test_a_reload_hands_the_engine_the_new_lines_and_changes_only_lines_held() -> None:
    async with service() as svc:
        svc.engine.grant("l1")
        await until(lambda: polled(svc, ("a1", "a2")))
        urls = {n: e.url for n, e in svc.ends.items()}
        svc.text[0] = config_text(urls, ("l1", "l3"))
        outcome = await svc.reloader.reload()
        assert outcome.loaded, outcome
        # said (and audited) though nothing of l3 runs here yet
        added = "line l3 added (started where it is mastered)"
        assert outcome.changes == ["line l2 removed", added]
        assert svc.engine.set == [["l1", "l3"]]
        assert "l3" not in svc.runtime.runners and svc.ends["l3"].connections == 0
        assert svc.ends["l1"].connections == 1  # l1 ran on, untouched
        r = await svc.client.get("/api/v1/lines")
        assert [x["name"] for x in r.json()] == ["l1", "l3"]
        text = await svc.metrics()
        assert set(series(text, "pkwbus_line_master")) == {(("line", "l1"),), (("line", "l3"),)}
        svc.engine.grant("l3")  # a line the reload added starts when won
        await until(lambda: polled(svc, ("c1",)))


async def test_a_single_instance_masters_every_line_and_names_no_master() -> None:
    """Without a standby section: every line runs from the start, pkwbus_line_master is 1
    for each, no standby series, and /api/v1/lines names no master."""
    async with single() as (runtime, registry, client):
        await until(lambda: all(runtime.snapshot.lines.get(n) for n in ("l1", "l2")))
        text = (await render(registry)).decode()
        assert series(text, "pkwbus_line_master") == {
            (("line", "l1"),): 1.0, (("line", "l2"),): 1.0,
        }  # fmt: skip
        assert "pkwbus_standby_" not in text
        r = await client.get("/api/v1/lines")
        assert [(x["name"], x["master"]) for x in r.json()] == [("l1", None), ("l2", None)]
        r = await client.get("/api/v1/drives/zz/parameters/16-13")
        assert r.status_code == 404


async def test_a_won_line_that_cannot_start_is_tried_again_while_held(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(standby_lines, "RETRY_FIRST", 0.05)
    monkeypatch.setattr(standby_lines, "RETRY_MAX", 0.1)
    async with service() as svc:
        build = svc.parts.build
        tried: list[str] = []

        async def failing(plan: Any) -> Any:
            tried.append(plan.line.name)
            if plan.line.name == "l2" or len(tried) <= 2:
                raise RuntimeError("the gateway's simulator did not come up")
            return await build(plan)

        monkeypatch.setattr(svc.parts, "build", failing)
        with caplog.at_level(logging.DEBUG, logger="pkwbus.service.standby"):
            svc.engine.grant("l1")
            await until(lambda: "l1" in svc.runtime.runners)
            await until(lambda: polled(svc, ("a1", "a2")))
        assert tried == ["l1", "l1", "l1"]
        errors = [r for r in caplog.records if r.levelno == logging.ERROR]
        assert len(errors) == 1 and "cannot start" in errors[0].getMessage()
        assert any("started at last" in r.getMessage() for r in caplog.records)
        # Lost while it cannot start: never tried again.
        svc.engine.grant("l2")
        await until(lambda: tried.count("l2") >= 2)
        svc.engine.lose("l2")
        await asyncio.sleep(0.1)  # let a retry already due run its course
        count = tried.count("l2")
        await asyncio.sleep(0.5)  # five times the longest delay
        assert tried.count("l2") == count and "l2" not in svc.runtime.runners
