"""Refused requests cannot exhaust anything: names longer than any drive or parameter
are refused before a lookup and never stored whole, requests without a valid token
are counted (a metric, one audit row per address and minute), error bodies quote
little, and the audit log is read with a token and in bounded pages."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import httpx
import pytest

from pkwbus.service.audit.log import MAX_SOURCES_PER_MINUTE, OTHER_SOURCES, AuditLog
from pkwbus.service.http.parameters import MAX_READS_PER_DRIVE
from pkwbus.sim import SimTiming
from tests.service.http.conftest import AUTH, TOKEN, Service, service
from tests.service.http.test_audit_store import metric

LONG = "x" * 7900
READ_TOKEN = "r3ad-Only-Token-for-the-audit-42"
NOW = 1_700_000_000.0


def db_bytes(audit: AuditLog) -> int:
    """The database's size with its write-ahead log folded in."""
    db = audit._db
    db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    pages = db.execute("PRAGMA page_count").fetchone()[0]
    size = db.execute("PRAGMA page_size").fetchone()[0]
    return int(pages * size)


async def test_refusals_without_a_token_are_counted_not_stored_one_by_one(
    tmp_path: Path,
) -> None:
    async with service(tmp_path) as svc:
        assert svc.audit is not None
        svc.audit.clock = lambda: NOW
        before = db_bytes(svc.audit)
        for i in range(200):
            headers = {} if i % 2 else {"Authorization": "Bearer guess"}
            r = await svc.put(LONG, LONG, {"value": 38}, headers=headers)
            assert r.status_code in (401, 403), r.text
            assert len(r.content) < 500
        assert db_bytes(svc.audit) - before <= 4 * 4096  # a row, not 200 of 16 KB
        (row,) = svc.audit.latest(10)
        assert (row.outcome, row.count, row.client) == ("refused", 200, "127.0.0.1")
        assert row.detail is not None
        assert "unauthenticated 100" in row.detail and "forbidden 100" in row.detail
        assert LONG not in json.dumps(row.__dict__)
        assert await metric(svc, "pkwbus_api_refusals_total", reason="unauthenticated") == 100
        assert await metric(svc, "pkwbus_api_refusals_total", reason="forbidden") == 100
        # the next minute has its own row
        svc.audit.clock = lambda: NOW + 60
        await svc.put("fan1", "3-41", {"value": 38}, headers={})
        assert [(e.count, e.time) for e in svc.audit.latest(10)] == [(1, NOW + 60), (200, NOW)]
        assert svc.audit_writer.writes() == []


def test_many_addresses_share_a_bounded_number_of_rows(tmp_path: Path) -> None:
    log = AuditLog(tmp_path / "a.sqlite", clock=lambda: NOW)
    try:
        for i in range(3 * MAX_SOURCES_PER_MINUTE):
            log.refused(f"2001:db8::{i:x}", "unauthenticated")
        rows = log.latest(1000)
    finally:
        log.close()
    assert len(rows) == MAX_SOURCES_PER_MINUTE + 1
    assert sum(r.count or 0 for r in rows) == 3 * MAX_SOURCES_PER_MINUTE
    (other,) = [r for r in rows if r.client == OTHER_SOURCES]
    assert other.count == 2 * MAX_SOURCES_PER_MINUTE


@pytest.mark.parametrize(
    ("drive", "parameter", "kind"),
    [(LONG, "3-41", "unknown_drive"), ("fan1", LONG, "unknown_parameter"), ("f" * 65, "1", "")],
    ids=["drive", "parameter", "drive_65"],
)
async def test_names_longer_than_any_are_refused_and_not_stored(
    tmp_path: Path, drive: str, parameter: str, kind: str
) -> None:
    async with service(tmp_path) as svc:
        r = await svc.put(drive, parameter, {"value": 38})
        assert r.status_code == 404, r.text
        error = r.json()["error"]
        assert error["kind"] == (kind or "unknown_drive")
        assert len(r.content) < 300
        read = await svc.client.get(f"/api/v1/drives/{drive}/parameters/{parameter}")
        assert read.status_code == 404 and len(read.content) < 300
        assert svc.audit_writer.writes() == []
        assert svc.audit is not None
        (row,) = svc.audit.latest(5)
        assert row.outcome == "invalid" and row.token_id is not None
        assert len(row.drive) <= 67 and len(row.parameter) <= 67
        assert drive.startswith(row.drive.removesuffix("..."))


async def test_error_bodies_quote_little(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        # a body within the size limit that names many unknown fields
        body = {"value": 1, **{f"field_{i:03d}_{'y' * 20}": 1 for i in range(100)}}
        r = await svc.put("fan1", "3-41", body)
        assert r.status_code == 422
        assert len(r.json()["error"]["message"]) <= 300
        r = await svc.put("fan1", "3-41", {"value": "\u20ac" * 500})  # not a number
        assert r.status_code == 422
        assert len(r.json()["error"]["message"]) <= 300
        assert svc.audit is not None
        assert all(len(e.detail or "") <= 600 for e in svc.audit.latest(10))


async def get_audit(svc: Service, **kw: object) -> httpx.Response:
    return await svc.client.get("/api/v1/audit", **kw)  # type: ignore[arg-type]


async def test_reading_the_audit_needs_a_token(tmp_path: Path) -> None:
    async with service(tmp_path, read_token=READ_TOKEN) as svc:
        await svc.put("fan1", "3-41", {"value": 38})
        assert (await get_audit(svc)).status_code == 401
        r = await get_audit(svc, headers={"Authorization": "Bearer guess"})
        assert r.status_code == 403 and r.json()["error"]["kind"] == "forbidden"
        for token in (TOKEN, READ_TOKEN):
            r = await get_audit(svc, headers={"Authorization": f"Bearer {token}"})
            assert r.status_code == 200, r.text
            assert [e["outcome"] for e in r.json()][-1] == "ok"
        # the read token cannot write
        r = await svc.put(
            "fan1", "3-41", {"value": 1}, headers={"Authorization": f"Bearer {READ_TOKEN}"}
        )
        assert r.status_code == 403
        assert svc.sim.drives[1].value(341) == 3800
        # bounded pages
        r = await get_audit(svc, params={"limit": 1000}, headers=AUTH)
        assert r.status_code == 200
        r = await get_audit(svc, params={"limit": 1001}, headers=AUTH)
        assert r.status_code == 422
        assert await metric(svc, "pkwbus_api_refusals_total", reason="unauthenticated") == 1
        assert await metric(svc, "pkwbus_api_refusals_total", reason="forbidden") == 2


async def test_without_any_token_the_audit_is_closed(tmp_path: Path) -> None:
    async with service(tmp_path, token=None) as svc:
        r = await get_audit(svc, headers=AUTH)
        assert r.status_code == 403
        assert "api.read_token_env" in r.json()["error"]["message"]


async def test_on_demand_reads_of_one_drive_are_bounded(tmp_path: Path) -> None:
    """Reads need no token and go ahead of polls: beyond a few waiting, 429."""
    async with service(tmp_path, timing=SimTiming(response_delay=0.05)) as svc:
        path = "/api/v1/drives/fan1/parameters/3-41"
        answers = await asyncio.gather(*(svc.client.get(path) for _ in range(12)))
        codes = [r.status_code for r in answers]
        assert codes.count(200) >= MAX_READS_PER_DRIVE and 429 in codes, codes
        assert set(codes) <= {200, 429}
        busy = next(r for r in answers if r.status_code == 429)
        assert busy.json()["error"]["kind"] == "busy"
        assert (await svc.client.get(path)).status_code == 200  # room again once answered
