"""Writes and maintenance switched through the HTTP API while a reload applies, in process
over simulated FC drives on TCP, measured at the drives.

A write checked against a drive's entry never goes to another drive: a reload that moves
the drive, changes its ``writable`` list or limits, or removes it between the checks and
the send refuses the write (nothing sent, its audit row completed, no error logged). A
maintenance the API began holds on the line that runs after a reload, whatever its reason,
also one switched while the line is being opened again, and outlasts the file's own flag
added and taken away; ``{"on": false}`` takes it out (README "A drive in maintenance",
"Reloading the configuration")."""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest

from pkwbus.master.planning.jobs import JobKind
from pkwbus.service.assembly.build import Parts
from pkwbus.service.assembly.line_marks import Kept, LineMarks
from pkwbus.service.assembly.reload import Reloader
from pkwbus.service.audit.log import AuditEntry, AuditLog
from pkwbus.service.http.api import build_api
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming, Simulator
from tests.service.assembly.test_reload_dp import reloadable, until
from tests.service.http.conftest import Recorder

TOKEN = "t0ken-of-the-reload-tests"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def fan(name: str, address: int, **extra: Any) -> dict[str, Any]:
    poll = [{"parameter": "16-13", "every": "100ms"}]
    return {"name": name, "address": address, "catalog": "danfoss-fc", "poll": poll,
            "writable": ["3-41"], **extra}  # fmt: skip


def fc_line(name: str, url: str, drives: list[dict[str, Any]], timeout: str) -> dict[str, Any]:
    return {
        "name": name, "port": url, "protocol": "fc", "baudrate": 115200, "timeout": timeout,
        "retries": 1, "alarms": "off", "settings": "off", "events": "off", "counters": "off",
        "drives": drives,
    }  # fmt: skip


@dataclass
class Plant:
    """Line ``fc`` (fan1 at 1, fan2 at 2; a drive at 3 answers too, unconfigured) and the
    API over it; :meth:`set` gives the file a reload reads."""

    url: str
    other_url: str  # a second simulator: line ``other`` (pump at 1) where a test adds it
    audit_path: Path
    heard: Recorder  # what reached the drives of line fc's simulator
    sim: Simulator
    runtime: Runtime
    parts: Parts
    reloader: Reloader
    audit: AuditLog
    client: httpx.AsyncClient
    api: Any
    text: list[str]

    def set(
        self, fan2: dict[str, Any] | None, *, timeout: str = "200ms", other: bool = False
    ) -> None:
        drives = [fan("fan1", 1)] + ([fan2] if fan2 is not None else [])
        lines = [fc_line("fc", self.url, drives, timeout)]
        if other:
            lines.append(fc_line("other", self.other_url, [fan("pump", 1)], "200ms"))
        self.text[0] = json.dumps({"audit_db": str(self.audit_path), "lines": lines})

    def writes_of_341(self, since: int) -> list[tuple[int, int]]:
        """(address, raw) of each write of 3-41 that reached a drive since ``since``."""
        return [(a, q.value) for a, q in self.heard.requests[since:] if q.pnu == 341 and q.is_write]

    def to(self, address: int, since: int) -> int:
        return sum(1 for a, _ in self.heard.requests[since:] if a == address)

    async def switch(self, on: bool, reason: str = "") -> httpx.Response:
        return await self.client.put(
            "/api/v1/drives/fan2/maintenance", json={"on": on, "reason": reason}, headers=AUTH
        )

    async def write(self, value: float) -> httpx.Response:
        return await self.client.put(
            "/api/v1/drives/fan2/parameters/3-41", json={"value": value}, headers=AUTH
        )

    def rows(self, parameter: str) -> list[AuditEntry]:
        return [row for row in self.audit.latest(20) if row.parameter == parameter]

    def when_recorded(self, then: Callable[[], Awaitable[object]]) -> None:
        """Run ``then`` once, inside the audit's store of the next row of fan2, after it
        is committed: between a request's checks and what it does."""
        writer = self.api.audit_writer
        attempt = writer.attempt
        ran: list[object] = []

        async def attempted(entry: AuditEntry) -> Any:
            row = await attempt(entry)
            if entry.drive == "fan2" and not ran:
                ran.append(await then())
            return row

        writer.attempt = attempted


@asynccontextmanager
async def plant(tmp_path: Path, fan2: dict[str, Any] | None = None) -> AsyncIterator[Plant]:
    async with AsyncExitStack() as stack:
        sim = Simulator("fc", [1, 2, 3], timing=SimTiming(response_delay=0.002), seed=3,
                        catalog="danfoss-fc")  # fmt: skip
        heard = Recorder()
        heard.attach(sim)
        end = await sim.serve_tcp("127.0.0.1", 0)
        stack.push_async_callback(end.close)
        other = Simulator("fc", [1], timing=SimTiming(response_delay=0.002), seed=4,
                          catalog="danfoss-fc")  # fmt: skip
        other_end = await other.serve_tcp("127.0.0.1", 0)
        stack.push_async_callback(other_end.close)
        text = [""]
        found = Plant(end.url, other_end.url, tmp_path / "audit.sqlite", heard, sim,
                      *([None] * 6), text)  # type: ignore[arg-type]  # fmt: skip
        found.set(fan2 or fan("fan2", 2))
        _, found.runtime, found.parts, found.reloader = await reloadable(text, stack)
        found.audit = AuditLog(found.audit_path)
        stack.callback(found.audit.close)
        found.api = build_api(found.runtime, audit=found.audit, write_token=TOKEN)
        found.client = httpx.AsyncClient(
            transport=httpx.ASGITransport(app=found.api.app, raise_app_exceptions=False),
            base_url="http://pkwbus.test", timeout=30.0,
        )  # fmt: skip
        stack.push_async_callback(found.client.aclose)
        await described(found.runtime)
        yield found


async def described(runtime: Runtime) -> None:
    """Until fan1 and fan2 described what they poll and write, and have values."""
    await until(lambda: {"fan1", "fan2"} <= {k[0] for k in runtime.snapshot.readings}
                and all(not d.pending for d in runtime.snapshot.decoding.values()))  # fmt: skip


def quiet(caplog: pytest.LogCaptureFixture) -> None:
    """Nothing went wrong in the service: no error logged, no traceback."""
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert errors == [] and "Traceback" not in caplog.text, errors


# ------------------------------------------------- a write checked, then a reload


@pytest.mark.parametrize(
    ("fan2", "change", "answer", "outcome"),
    [
        (fan("fan2", 3), "line fc: drive fan2 replaced", (503, "cancelled"), "cancelled"),
        (fan("fan2", 2, writable=["3-42"]), "line fc: drive fan2: writable parameters changed",
         (503, "cancelled"), "cancelled"),
        (fan("fan2", 2, parameters={"3-41": {"min": 1, "max": 10}}),
         "line fc: drive fan2: parameter overrides changed", (503, "cancelled"), "cancelled"),
        (None, "line fc: drive fan2 removed", (404, "unknown_drive"), "invalid"),
    ],
    ids=["moved", "not-writable", "limited", "removed"],
)  # fmt: skip
async def test_a_write_checked_before_a_reload_changed_its_drive_is_not_sent(
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    fan2: dict[str, Any] | None,
    change: str | None,
    answer: tuple[int, str],
    outcome: str,
) -> None:
    """The reload applies while the write's row is being stored: after the write was checked
    against fan2 at address 2, writable, without limits, and before it is queued."""
    caplog.set_level(logging.INFO)
    async with plant(tmp_path) as p:
        reloads: list[Any] = []

        async def reload() -> None:
            p.set(fan2)
            reloads.append(await p.reloader.reload())

        p.when_recorded(reload)
        before, held = len(p.heard.requests), [p.sim.drives[a].value(341) for a in (2, 3)]
        r = await p.write(42.5)
        assert reloads[0].changes == ([change] if change else [])
        assert (r.status_code, r.json()["error"]["kind"]) == answer, r.text
        await asyncio.sleep(0.3)  # a write that went out anyway would have landed by now
        assert p.writes_of_341(before) == []
        assert [p.sim.drives[a].value(341) for a in (2, 3)] == held
        (row,) = p.rows("3-41")
        assert row.outcome == outcome and "nothing was sent" in (row.detail or ""), row
    quiet(caplog)


async def test_a_write_during_a_reload_goes_to_the_drive_it_was_checked_against(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A reload moves fan2 to address 3 on its running line and adds a line whose start
    takes a while: a write of fan2 checked meanwhile (the reload not applied yet) goes to
    address 2, where fan2 was when it was checked, never to 3. (fan2 describes nothing: a
    drive that does is refused while it describes itself anew, which would hide it.)"""
    async with plant(tmp_path, fan("fan2", 2, describe="off")) as p:
        build = p.parts.build
        answers: list[httpx.Response] = []
        before = len(p.heard.requests)

        async def slow(plan: Any) -> Any:
            if plan.line.name == "other":  # the reload is under way: fan2 still at 2
                answers.append(await p.write(42.5))
            return await build(plan)

        p.parts.build = slow  # type: ignore[method-assign]
        p.set(fan("fan2", 3, describe="off"), other=True)
        outcome = await p.reloader.reload()
        assert p.writes_of_341(before) == [(2, 4250)]
        assert p.sim.drives[2].value(341) == 4250
        assert answers[0].status_code == 200, answers[0].text
        assert outcome.changes == ["line fc: drive fan2 replaced", "line other added"]
    quiet(caplog)


async def test_a_verified_write_is_not_read_back_from_a_drive_a_reload_changed(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The write reached fan2 at address 2; a reload moves fan2 to address 3 before its
    read-back: nothing is read from address 3, the write is answered and audited
    unverified."""
    async with plant(tmp_path) as p:
        submit = p.runtime.submit

        async def reload_after(*args: Any, **kwargs: Any) -> Any:
            result = await submit(*args, **kwargs)
            if args[2] is JobKind.WRITE:
                p.set(fan("fan2", 3))
                await p.reloader.reload()
            return result

        p.runtime.submit = reload_after  # type: ignore[assignment,method-assign]
        before = len(p.heard.requests)
        r = await p.client.put("/api/v1/drives/fan2/parameters/3-41",
                               json={"value": 42.5, "verify": True}, headers=AUTH)  # fmt: skip
        assert r.status_code == 200 and r.json()["verified"] is False, r.text
        assert p.sim.drives[2].value(341) == 4250
        assert [q for a, q in p.heard.requests[before:] if a == 3 and q.pnu == 341] == []
        (row,) = p.rows("3-41")
        assert row.outcome == "unverified", row
    quiet(caplog)


async def test_maintenance_of_a_drive_a_reload_removed_meanwhile(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    async with plant(tmp_path) as p:

        async def reload() -> None:
            p.set(None)
            await p.reloader.reload()

        p.when_recorded(reload)
        r = await p.switch(True, "bearing change")
        assert (r.status_code, r.json()["error"]["kind"]) == (404, "unknown_drive"), r.text
        (row,) = p.rows("maintenance")
        assert row.outcome == "invalid" and "removed" in (row.detail or "")
        assert "fan2" not in p.runtime.snapshot.maintenance
        assert "fan2" not in p.runtime.api_maintenance
    quiet(caplog)


# -------------------------------------------------- maintenance across a reload


@pytest.mark.parametrize("when", ["stopped", "building"])
async def test_maintenance_switched_while_the_line_is_opened_again_holds(
    tmp_path: Path, when: str
) -> None:
    """The reload opens line fc again (its timeout changed); the API puts fan2 in
    maintenance once the old line stopped, or while the new one is being built: from its
    answer on, nothing goes to fan2. ``{"on": false}`` then brings it back."""
    async with plant(tmp_path) as p:
        answers: list[httpx.Response] = []
        stop_line, build = p.reloader._stop_line, p.parts.build

        async def stopping(name: str, next_load: Any) -> None:
            await stop_line(name, next_load)
            if when == "stopped":
                answers.append(await p.switch(True, "bearing change"))

        async def building(plan: Any) -> Any:
            if when == "building":
                answers.append(await p.switch(True, "bearing change"))
            return await build(plan)

        p.reloader._stop_line = stopping  # type: ignore[method-assign]
        p.parts.build = building  # type: ignore[method-assign]
        p.set(fan("fan2", 2), timeout="300ms")
        outcome = await p.reloader.reload()
        assert outcome.changes == ["line fc reopened"]
        assert answers[0].status_code == 200 and answers[0].json()["on"] is True
        since = answers[0].json()["since"]
        assert p.runtime.snapshot.maintenance["fan2"].reason == "bearing change"
        assert p.runtime.snapshot.maintenance["fan2"].since == since
        after = len(p.heard.requests)
        await until(lambda: p.to(1, after) >= 5)  # the line runs: fan1 is polled
        assert p.to(2, after) == 0, "a telegram went to fan2 in maintenance"
        refused = await p.write(12)
        assert (refused.status_code, refused.json()["error"]["kind"]) == (409, "in_maintenance")

        off = await p.switch(False)
        assert off.status_code == 200 and off.json()["on"] is False
        assert "fan2" not in p.runtime.snapshot.maintenance
        back = len(p.heard.requests)
        await until(lambda: p.to(2, back) >= 1)
        await described(p.runtime)
        assert (await p.write(12)).status_code == 200


@pytest.mark.parametrize("reason", ["bearing change", "configuration"])
async def test_a_maintenance_the_api_began_survives_a_reopen_whatever_its_reason(
    tmp_path: Path, reason: str
) -> None:
    async with plant(tmp_path) as p:
        began = (await p.switch(True, reason)).json()
        p.set(fan("fan2", 2), timeout="300ms")
        assert (await p.reloader.reload()).changes == ["line fc reopened"]
        held = p.runtime.snapshot.maintenance["fan2"]
        assert (held.reason, held.since) == (reason, began["since"])
        after = len(p.heard.requests)
        await until(lambda: p.to(1, after) >= 5)
        assert p.to(2, after) == 0
        r = await p.write(12)
        assert (r.status_code, r.json()["error"]["kind"]) == (409, "in_maintenance")


@pytest.mark.parametrize("reopen", [True, False], ids=["reopened", "in-place"])
async def test_the_files_flag_added_then_taken_away_leaves_the_apis_maintenance(
    tmp_path: Path, reopen: bool
) -> None:
    """The API puts fan2 in maintenance; a reload adds ``maintenance: true`` to it (with its
    line opened again, or in place), a later one takes the flag away: fan2 stays in the
    API's maintenance, its reason and since as the API began it, until the API ends it."""
    async with plant(tmp_path) as p:
        began = (await p.switch(True, "configuration")).json()
        p.set(fan("fan2", 2, maintenance=True), timeout="300ms" if reopen else "200ms")
        await p.reloader.reload()
        p.set(fan("fan2", 2), timeout="300ms" if reopen else "200ms")
        assert (await p.reloader.reload()).changes == []
        held = p.runtime.snapshot.maintenance.get("fan2")
        assert held is not None and (held.reason, held.since) == ("configuration", began["since"])
        after = len(p.heard.requests)
        await until(lambda: p.to(1, after) >= 5)
        assert p.to(2, after) == 0
        assert (await p.switch(False)).json()["on"] is False
        back = len(p.heard.requests)
        await until(lambda: p.to(2, back) >= 1)
        assert "fan2" not in p.runtime.snapshot.maintenance


async def test_the_files_flag_taken_away_still_ends_the_files_maintenance(tmp_path: Path) -> None:
    """Where the API never put it in maintenance, the flag taken away takes fan2 out."""
    async with plant(tmp_path) as p:
        p.set(fan("fan2", 2, maintenance=True))
        await p.reloader.reload()
        assert p.runtime.snapshot.maintenance["fan2"].reason == "configuration"
        p.set(fan("fan2", 2))
        assert "line fc: drive fan2 out of maintenance" in (await p.reloader.reload()).changes
        assert "fan2" not in p.runtime.snapshot.maintenance
        back = len(p.heard.requests)
        await until(lambda: p.to(2, back) >= 1)


class _NoMarks:
    """etcd's marks, none kept: what LineMarks reads and writes, for the maintenance only."""

    async def get(self, line: str, name: str) -> bytes | None:
        return None

    async def put(self, line: str, name: str, value: bytes) -> bool:
        return True


async def test_a_maintenance_carried_from_the_other_master_is_kept_as_the_apis(
    tmp_path: Path,
) -> None:
    """Hot standby: a line won carries the other instance's maintenance (its marks give the
    reason only). The API's there is the API's here: a reload that opens the line again
    keeps it; the line lost, its next master keeps it, not this instance."""
    async with plant(tmp_path) as p:
        marks = LineMarks(_NoMarks(), p.runtime, None, lambda line: ["fan1", "fan2"])
        marks.maintained("fc", {"fan2": Kept("bearing change", by_api=True)})
        held = p.runtime.snapshot.maintenance["fan2"]
        assert held.reason == "bearing change"
        p.set(fan("fan2", 2), timeout="300ms")  # the line's port opened again
        assert (await p.reloader.reload()).changes == ["line fc reopened"]
        assert p.runtime.snapshot.maintenance.get("fan2") == held  # its reason and since
        await marks.release("fc", flush=False)
        assert "fan2" not in p.runtime.api_maintenance
