"""GET /api/v1/events: the drives' own log entries as kept, newest first, filtered."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import httpx
import pytest
from prometheus_client import CollectorRegistry

from pkwbus.master.snapshot import Snapshot
from pkwbus.master.target import DriveTarget
from pkwbus.service.history.store import DriveEvent, HistoryStore
from pkwbus.service.http.api import create_app
from pkwbus.service.runtime import DriveEntry, Load, Runtime

T0 = 1_794_902_400.0  # 2026-11-17T08:00:00Z


def event(drive: str, number: int, time: float | None, seen: float) -> DriveEvent:
    source = "runtime" if time is not None else "seen"
    return DriveEvent(
        "l1", drive, f"fault|{number}", "fault", f"F{number:05d}", number, "", number % 7, time,
        source, "1 d 00:00:00.000" if time is not None else "", seen,
    )  # fmt: skip


@pytest.fixture
async def client(tmp_path: Path) -> AsyncIterator[httpx.AsyncClient]:
    drives = [DriveEntry(name, "l1", DriveTarget.create("uss", i)) for i, name in enumerate("ab")]
    store = HistoryStore(tmp_path / "history.sqlite")
    store.add([
        event("a", 7801, T0 + 10, T0 + 500),
        event("a", 7802, None, T0 + 400),
        event("b", 30001, T0 + 600, T0 + 700),
    ])  # fmt: skip
    load = Load(drives={d.name: d for d in drives}, history=store)
    runtime = Runtime(Snapshot(), CollectorRegistry(), load)
    app = create_app(runtime, audit=None, write_token=None, read_token=None)
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://pkwbus") as client:
        yield client
    store.close()


async def test_newest_first_with_the_time_each_entry_has(client: httpx.AsyncClient) -> None:
    found = (await client.get("/api/v1/events")).json()["events"]
    assert [e["code"] for e in found] == ["F30001", "F07802", "F07801"]
    by_code = {e["code"]: e for e in found}
    assert by_code["F07801"]["time"] == "2026-11-17T08:00:10.000Z"
    assert by_code["F07801"]["time_source"] == "runtime"
    assert by_code["F07801"]["seen"] == "2026-11-17T08:08:20.000Z"
    # No usable time in the log: its time is when pkwbus first read it.
    assert by_code["F07802"]["time"] == by_code["F07802"]["seen"] == "2026-11-17T08:06:40.000Z"
    assert by_code["F07802"]["time_source"] == "seen"
    assert set(by_code["F07801"]) == {
        "line", "drive", "kind", "code", "text", "value", "time", "time_source", "drive_time",
        "seen",
    }  # fmt: skip


async def test_filters_drive_since_and_limit(client: httpx.AsyncClient) -> None:
    def codes(query: str) -> list[str]:
        return [e["code"] for e in client_get[query]]

    client_get = {
        q: (await client.get("/api/v1/events", params=dict([q.split("=", 1)]))).json()["events"]
        for q in (
            "drive=a",
            "since=2026-11-17T08:05:00Z",
            "limit=1",
            "since=2026-11-17T09:00:05+01:00",
        )
    }
    assert codes("drive=a") == ["F07802", "F07801"]
    assert codes("since=2026-11-17T08:05:00Z") == ["F30001", "F07802"]
    assert codes("limit=1") == ["F30001"]
    assert codes("since=2026-11-17T09:00:05+01:00") == ["F30001", "F07802", "F07801"]  # 08:00:05Z


async def test_bad_requests_get_a_clear_answer(client: httpx.AsyncClient) -> None:
    unknown = await client.get("/api/v1/events?drive=nobody")
    assert unknown.status_code == 404 and unknown.json()["error"]["kind"] == "unknown_drive"
    bad = await client.get("/api/v1/events?since=yesterday")
    assert bad.status_code == 422 and "ISO 8601" in bad.json()["error"]["message"]
    assert (await client.get("/api/v1/events?limit=0")).status_code == 422
