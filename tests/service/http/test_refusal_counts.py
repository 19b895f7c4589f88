"""Requests refused for want of a valid token are counted in memory and written once per
address and minute: when the minute has ended (the next refusal, or a timer), before an
authorised read, and when the log is closed. Nothing counted is lost while the log cannot
record, and the write-ahead log stays small."""

from __future__ import annotations

import logging
import sqlite3
import time
from pathlib import Path

import pytest

from pkwbus.service.audit.log import WAL_BYTES, WAL_PAGES, AuditEntry, AuditError, AuditLog
from pkwbus.service.audit.refusals import RefusalTallies
from tests.service.http.test_audit_store import FULL, failing

NOW = 1_700_000_000.0  # 20 s into a minute
DETAIL = "refused without a valid token: "


class Clock:
    def __init__(self, now: float = NOW) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def stored(db: Path) -> list[tuple[str, float, int, str]]:
    """The refusal rows as another connection sees them: committed ones."""
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as look:
        return look.execute(
            "SELECT client, time, count, detail FROM writes WHERE outcome = 'refused' ORDER BY id"
        ).fetchall()


def test_refusals_are_written_once_their_minute_has_ended(tmp_path: Path) -> None:
    clock = Clock()
    log = AuditLog(tmp_path / "a.sqlite", clock=clock)
    statements: list[str] = []
    try:
        log._db.set_trace_callback(statements.append)
        for i in range(1000):
            clock.now = NOW + i / 100  # within the minute
            log.refused("10.0.0.9", "forbidden" if i % 4 == 0 else "unauthenticated")
        log.refused("10.0.0.8", "unauthenticated")
        assert statements == [], "a refusal was written before its minute ended"
        clock.now = NOW + 60
        log.refused("10.0.0.9", "unauthenticated")  # a later minute: the last one is written
        assert statements[0] == "BEGIN IMMEDIATE" and statements[-1] == "COMMIT"
        assert len([s for s in statements if s.startswith("INSERT")]) == 2
        assert log._db.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL: synced
        statements.clear()
        for _ in range(100):
            log.refused("10.0.0.9", "unauthenticated")
        assert statements == []
        assert len(stored(log.path)) == 2
    finally:
        log.close()  # writes the minute that has not ended
    assert stored(log.path) == [
        ("10.0.0.9", NOW, 1000, DETAIL + "forbidden 250, unauthenticated 750"),
        ("10.0.0.8", NOW + 9.99, 1, DETAIL + "unauthenticated 1"),
        ("10.0.0.9", NOW + 60, 101, DETAIL + "unauthenticated 101"),
    ]


def test_a_read_writes_the_counts_first_and_their_row_is_kept(tmp_path: Path) -> None:
    clock = Clock()
    log = AuditLog(tmp_path / "a.sqlite", clock=clock)
    try:
        log.record(AuditEntry("10.0.0.1", "fan1", "3-41", 0, "ok", time=NOW - 1))
        log.refused("10.0.0.9", "unauthenticated")
        first = log.latest(5)
        assert [(e.outcome, e.count) for e in first] == [("refused", 1), ("ok", None)]
        for _ in range(4):
            log.refused("10.0.0.9", "forbidden")
        assert stored(log.path)[0][2] == 1  # more this minute: written when it ends
        clock.now = NOW + 60
        assert log.flush() == 4
        assert log.flush() == 0
        again = log.latest(5)
    finally:
        log.close()
    assert [(e.id, e.count) for e in again] == [(first[0].id, 5), (first[1].id, None)]
    assert again[0].detail == DETAIL + "forbidden 4, unauthenticated 1"


def test_a_timer_writes_a_minute_that_no_refusal_follows(tmp_path: Path) -> None:
    # a clock at real pace, a third of a second before a minute's end
    start = time.monotonic()
    base = (int(time.time() // 60) + 10) * 60 - 0.3
    log = AuditLog(tmp_path / "a.sqlite", clock=lambda: base + time.monotonic() - start)
    try:
        log.refused("10.0.0.9", "unauthenticated")
        assert stored(log.path) == []
        deadline = time.monotonic() + 30
        while not stored(log.path):  # the timer, 1 s after the minute's end
            assert time.monotonic() < deadline, "the ended minute's count was not written"
            time.sleep(0.05)
        ((client, at, count, _),) = stored(log.path)
        assert (client, count) == ("10.0.0.9", 1) and at < base + 0.3
    finally:
        log.close()


def test_counts_that_cannot_be_written_are_kept_until_they_can(tmp_path: Path) -> None:
    clock = Clock()
    log = AuditLog(tmp_path / "a.sqlite", clock=clock)
    conn = failing(log)
    conn.fail = {"INSERT"}
    try:
        log.refused("10.0.0.9", "unauthenticated")
        clock.now = NOW + 60
        with pytest.raises(AuditError, match=FULL):
            log.refused("10.0.0.9", "unauthenticated")  # the last minute cannot be written
        with pytest.raises(AuditError, match=FULL):
            log.refused("10.0.0.9", "unauthenticated")  # still failing: not tried per request
        assert conn.failed == 1
        conn.fail = set()
        log.probe()  # a store that succeeds: the log records again
        log.refused("10.0.0.9", "unauthenticated")
    finally:
        log.close()
    assert [(t, n) for _, t, n, _ in stored(log.path)] == [(NOW, 1), (NOW + 60, 3)]


def test_a_log_closed_that_cannot_store_says_how_many_counts_are_lost(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    log = AuditLog(tmp_path / "a.sqlite", clock=Clock())
    for _ in range(7):
        log.refused("10.0.0.9", "unauthenticated")
    failing(log).fail = {"INSERT"}
    log.close()  # no exception: the service is stopping
    told = [r.getMessage() for r in caplog.records if r.levelno == logging.ERROR]
    assert told == [f"audit log: the counts of 7 refused request(s) cannot be stored: {FULL}"], told
    assert not [r for r in caplog.records if r.exc_info]


def test_tallies_of_a_log_that_cannot_record_are_bounded() -> None:
    tallies = RefusalTallies(max_minutes=2)
    for minute in range(3):
        for _ in range(minute + 1):
            tallies.count(NOW + 60 * minute, "10.0.0.9", "unauthenticated")
    assert tallies.pending() == 6
    (dropped,) = tallies.give_up()
    assert (dropped.time, dropped.count) == (NOW, 1)
    assert tallies.pending() == 5
    assert [t.count for t in tallies.due()] == [2, 3]
    assert tallies.give_up() == []


def test_the_write_ahead_log_stays_small(tmp_path: Path) -> None:
    log = AuditLog(tmp_path / "a.sqlite")
    wal = tmp_path / "a.sqlite-wal"
    largest = 0
    try:
        assert log._db.execute("PRAGMA wal_autocheckpoint").fetchone()[0] == WAL_PAGES
        assert log._db.execute("PRAGMA journal_size_limit").fetchone()[0] == WAL_BYTES
        for i in range(400):  # synced writes, each a transaction of its own
            row = log.record(AuditEntry("10.0.0.1", "fan1", "3-41", 0, "pending", new_value=i))
            log.update(row, outcome="ok")
            largest = max(largest, wal.stat().st_size)
    finally:
        log.close()
    page = 4096
    assert largest <= WAL_BYTES + 8 * page, largest  # without a bound: some 3 MB
