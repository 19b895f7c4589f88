"""An audit log that cannot store: a write is sent only after its row is stored.

The SQLite connection of the audit log fails its writes the way a full disk
does (``database or disk is full``): the write is refused with 503 and a JSON
reason, nothing reaches the drive, ``pkwbus_audit_errors_total`` counts it,
``/readyz`` says writes are unavailable until a store succeeds again. An
outcome that cannot be stored after the drive answered leaves the row
pending, is logged once and makes the answer say ``"audit": "incomplete"``.
The real full file system is in tests/reliability/test_audit_disk.py.
"""

from __future__ import annotations

import logging
import sqlite3
from pathlib import Path
from typing import Any

import pytest
from prometheus_client.parser import text_string_to_metric_families

from pkwbus.service.audit.log import AuditLog
from tests.service.http.conftest import Service, service

FULL = "database or disk is full"
NOW = 1_700_000_000.0


class FailingConnection:
    """The audit log's SQLite connection, failing the statements named in ``fail``
    (by their first word: INSERT, UPDATE) as SQLite does on a full disk."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self.db = db
        self.fail: set[str] = set()
        self.failed = 0

    def execute(self, sql: str, *args: Any) -> sqlite3.Cursor:
        if sql.split(None, 1)[0].upper() in self.fail:
            self.failed += 1
            raise sqlite3.OperationalError(FULL)
        return self.db.execute(sql, *args)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.db, name)


def failing(audit: AuditLog | None) -> FailingConnection:
    assert audit is not None
    conn = FailingConnection(audit._db)
    audit._db = conn  # type: ignore[assignment]
    return conn


async def metric(svc: Service, name: str, **labels: str) -> float:
    text = (await svc.client.get("/metrics")).text
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            if sample.name == name and all(sample.labels.get(k) == v for k, v in labels.items()):
                return sample.value
    raise AssertionError(f"no {name}{labels} in /metrics")


def no_traceback(caplog: pytest.LogCaptureFixture) -> None:
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"
    assert "Traceback" not in caplog.text


async def test_a_write_whose_row_cannot_be_stored_is_not_sent(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)
    async with service(tmp_path) as svc:
        drive = svc.sim.drives[1]
        before = drive.value(341)
        assert (await svc.client.get("/readyz")).status_code == 200
        assert await metric(svc, "pkwbus_audit_errors_total", stage="attempt") == 0
        conn = failing(svc.audit)
        conn.fail = {"INSERT", "UPDATE"}  # a probe by /readyz fails too

        r = await svc.put("fan1", "3-41", {"value": 38})
        assert r.status_code == 503, r.text
        error = r.json()["error"]
        assert error["kind"] == "audit_unavailable"
        assert FULL in error["message"] and "nothing was sent" in error["message"]
        assert svc.audit_writer.writes() == [], "the write reached the drive"
        assert svc.audit_writer.for_pnu(1, 341) == []
        assert drive.value(341) == before
        assert await metric(svc, "pkwbus_audit_errors_total", stage="attempt") == 1

        ready = await svc.client.get("/readyz")
        assert ready.status_code == 503
        body = ready.json()
        assert body["ready"] is False and body["writes"] is False
        assert FULL in body["reason"]
        assert all(body["lines"].values())  # the lines are fine: only writes are not
        lines = [r for r in caplog.records if "nothing was sent" in r.getMessage()]
        assert len(lines) == 1 and lines[0].levelno == logging.WARNING
        no_traceback(caplog)

        # Room again: /readyz tries a small store (here at once) and recovers.
        conn.fail = set()
        svc.api.audit_writer.probe_interval = 0.0
        ready = await svc.client.get("/readyz")
        assert ready.status_code == 200, ready.text
        assert ready.json()["writes"] is True and ready.json()["reason"] is None
        r = await svc.put("fan1", "3-41", {"value": 38})
        assert r.status_code == 200, r.text
        assert r.json()["audit"] == "complete"
        assert drive.value(341) == 3800
        assert svc.audit is not None
        assert [e.outcome for e in svc.audit.latest(5)] == ["ok"]


async def test_a_later_write_that_is_stored_makes_the_service_ready_again(
    tmp_path: Path,
) -> None:
    async with service(tmp_path) as svc:
        conn = failing(svc.audit)
        conn.fail = {"INSERT"}
        assert (await svc.put("fan1", "3-41", {"value": 1})).status_code == 503
        assert (await svc.client.get("/readyz")).status_code == 503
        conn.fail = set()
        assert (await svc.put("fan1", "3-41", {"value": 2})).status_code == 200
        assert (await svc.client.get("/readyz")).status_code == 200
        assert svc.sim.drives[1].value(341) == 200


@pytest.mark.parametrize(
    ("parameter", "value", "status", "outcome"),
    [("3-41", 11.5, 200, "ok"), ("1-20", 5000, 409, "rejected")],
    ids=["ok", "rejected"],
)
async def test_an_outcome_that_cannot_be_stored_leaves_the_row_pending(
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    parameter: str,
    value: float,
    status: int,
    outcome: str,
) -> None:
    caplog.set_level(logging.INFO)
    async with service(tmp_path) as svc:
        conn = failing(svc.audit)
        conn.fail = {"UPDATE"}  # the pending row is stored, its outcome is not
        r = await svc.put("fan1", parameter, {"value": value})
        assert r.status_code == status, r.text
        assert r.json()["audit"] == "incomplete"
        assert conn.failed == 4  # tried again, briefly
        assert len(svc.audit_writer.writes(1)) == 1  # it was sent: its row was stored first
        assert svc.audit is not None
        (row,) = svc.audit.latest(5)
        assert row.outcome == "pending"
        assert await metric(svc, "pkwbus_audit_errors_total", stage="outcome") == 1
        told = [r for r in caplog.records if "stays pending" in r.getMessage()]
        assert len(told) == 1, "the failure is told once"
        assert outcome in told[0].getMessage() and FULL in told[0].getMessage()
        no_traceback(caplog)

        # When the log records again, the kept outcome is stored.
        conn.fail = set()
        svc.api.audit_writer.probe_interval = 0.0
        assert (await svc.client.get("/readyz")).status_code == 200
        (row,) = svc.audit.latest(5)
        assert row.outcome == outcome


async def test_refused_and_invalid_attempts_say_when_they_are_not_audited(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)
    async with service(tmp_path) as svc:
        assert svc.audit is not None
        svc.audit.clock = lambda: NOW
        conn = failing(svc.audit)
        conn.fail = {"INSERT", "UPDATE"}
        for _ in range(10):  # without a token: counted in memory, nothing stored yet
            r = await svc.put("fan1", "3-41", {"value": 1}, headers={})
            assert r.status_code == 401
            assert "audit" not in r.json()
        assert conn.failed == 0
        svc.audit.clock = lambda: NOW + 60  # the minute's count cannot be stored: told once
        for _ in range(20):
            r = await svc.put("fan1", "3-41", {"value": 1}, headers={})
            assert r.status_code == 401
            assert r.json()["audit"] == "incomplete"
        r = await svc.put("fan1", "3-41", {"value": -1})
        assert r.status_code == 422
        assert r.json()["audit"] == "incomplete"
        r = await svc.put("fan1", "3-41", {"value": 1, "dry_run": True})
        assert r.status_code == 200
        assert r.json()["audit"] == "incomplete"
        assert svc.audit_writer.writes() == []
        assert await metric(svc, "pkwbus_audit_errors_total", stage="refusals") == 20
        assert await metric(svc, "pkwbus_api_refusals_total", reason="unauthenticated") == 30
        told = [r for r in caplog.records if "audit log cannot record" in r.getMessage()]
        assert len(told) == 3  # the start of the trouble, then the two attempts with the token
        no_traceback(caplog)

        # Room again: every refusal counted meanwhile is stored, none lost.
        conn.fail = set()
        svc.api.audit_writer.probe_interval = 0.0
        assert (await svc.client.get("/readyz")).status_code == 200
        rows = [(e.time, e.count) for e in svc.audit.latest(5) if e.outcome == "refused"]
        assert rows == [(NOW + 60, 20), (NOW, 10)]
