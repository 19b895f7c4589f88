"""The history database: each entry of a drive's own log, once (SQLite, WAL).

An entry is known by its drive and its content (kind, code, value, drive
time), never by where it sat in the drive's log; storing what is already
there changes nothing, so a sweep after a restart, an outage or a power
cycle adds only what is new. Every store is one synced transaction
(:mod:`pkwbus.service.audit.synced`): a killed service or a power cut loses
no entry it had counted. The store is bounded by a retention: entries first seen longer
ago than it are dropped, but only once the drive's log no longer holds them
(else they would be found again and counted twice).

Thread-safe: the service calls it off the event loop. Raises
:class:`HistoryError` (one line) when the database cannot be opened or
written.
"""

from __future__ import annotations

import contextlib
import sqlite3
import threading
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from pkwbus.errors import PkwbusError
from pkwbus.service.audit.synced import connect_synced

__all__ = [
    "EVENTS",
    "EVENT_COLUMNS",
    "SCHEMA",
    "SETTINGS",
    "Changes",
    "DriveEvent",
    "HistoryError",
    "HistoryStore",
    "event_row",
    "insert_events",
    "synced_transaction",
]

SCHEMA: Final = """
CREATE TABLE IF NOT EXISTS events (
    id INTEGER PRIMARY KEY,
    line TEXT NOT NULL,
    drive TEXT NOT NULL,
    key TEXT NOT NULL,
    kind TEXT NOT NULL,
    code TEXT NOT NULL,
    number INTEGER NOT NULL,
    text TEXT NOT NULL,
    value INTEGER,
    time REAL,
    time_source TEXT NOT NULL,
    drive_time TEXT NOT NULL,
    seen REAL NOT NULL,
    UNIQUE (drive, key)
);
CREATE INDEX IF NOT EXISTS events_drive_seen ON events (drive, seen);
"""

EVENT_COLUMNS = (
    "line, drive, key, kind, code, number, text, value, time, time_source, drive_time, seen"
)


@dataclass(frozen=True, slots=True)
class DriveEvent:
    """One entry of a drive's log as kept: ``code`` as the drive's documents show it
    (F07801), ``text`` from the vendor's table (empty where none explains it), ``time``
    the wall clock from the drive's own time base (None: ``time_source`` is ``seen``),
    ``drive_time`` as the drive gave it, ``seen`` when pkwbus first read it; ``key`` its
    identity: its content."""

    line: str
    drive: str
    key: str
    kind: str
    code: str
    number: int
    text: str
    value: int | None
    time: float | None
    time_source: str
    drive_time: str
    seen: float

    @property
    def when(self) -> float:
        """Its time where the drive gives one, else when pkwbus first read it."""
        return self.time if self.time is not None else self.seen


def event_row(e: DriveEvent) -> tuple[object, ...]:
    """``e`` as a row of the events table, in :data:`EVENT_COLUMNS`' order."""
    return (e.line, e.drive, e.key, e.kind, e.code, e.number, e.text, e.value, e.time,
            e.time_source, e.drive_time, e.seen)  # fmt: skip


def insert_events(db: sqlite3.Connection, events: Iterable[DriveEvent]) -> list[DriveEvent]:
    """Insert ``events`` in the transaction under way; those that were new."""
    sql = f"INSERT OR IGNORE INTO events ({EVENT_COLUMNS}) VALUES ({', '.join('?' * 12)})"
    return [e for e in events if db.execute(sql, event_row(e)).rowcount]


@contextlib.contextmanager
def synced_transaction(db: sqlite3.Connection, lock: threading.Lock, path: Path) -> Iterator[None]:
    """One transaction of ``db`` under ``lock``: committed at the end, rolled back on an
    error, which is a :class:`HistoryError` naming ``path``."""
    with lock:
        try:
            db.execute("BEGIN IMMEDIATE")
            yield
            db.execute("COMMIT")
        except sqlite3.Error as exc:
            with contextlib.suppress(sqlite3.Error):
                db.execute("ROLLBACK")
            raise HistoryError(f"history database {path}: {exc}") from None


class HistoryError(PkwbusError):
    """The history database cannot be opened or written."""


EVENTS: Final = "events"  # what :class:`Changes` counts: a drive's kept log entries
SETTINGS: Final = "settings"  # a drive's settings, baselines and last sweep


class Changes:
    """How many times each drive's kept log entries (:data:`EVENTS`) and settings
    (:data:`SETTINGS`) changed in the database, counted by the stores once a change is
    committed: who carries what is kept (a line's marks in hot standby) reads again only
    when a count moved. Thread-safe; counts only go up."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: dict[tuple[str, str], int] = {}

    def changed(self, part: str, drives: Iterable[str]) -> None:
        """``drives``' ``part`` changed (committed)."""
        with self._lock:
            for drive in set(drives):
                self._counts[(part, drive)] = self._counts.get((part, drive), 0) + 1

    def count(self, part: str, drives: Iterable[str]) -> int:
        """How many changes of ``drives``' ``part`` were counted."""
        counts = self._counts
        return sum(counts.get((part, drive), 0) for drive in drives)


class HistoryStore:
    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()
        self.changes = Changes()  # what changed in it (a settings' store given it counts too)
        try:
            self._db = connect_synced(path, SCHEMA)
        except (sqlite3.Error, OSError) as exc:
            raise HistoryError(f"cannot open the history database {self.path}: {exc}") from None

    def add(self, events: Sequence[DriveEvent]) -> list[DriveEvent]:
        """Store ``events`` in one synced transaction; those that were new (each entry is
        stored once, whatever the number of times it is offered)."""
        if not events:
            return []
        with synced_transaction(self._db, self._lock, self.path):
            new = insert_events(self._db, events)
        self.changes.changed(EVENTS, (e.drive for e in new))
        return new

    def known(self, drive: str) -> set[str]:
        """The keys of the entries kept of ``drive``."""
        rows = self._query("SELECT key FROM events WHERE drive = ?", (drive,))
        return {row[0] for row in rows}

    def latest(
        self, *, drive: str | None = None, since: float | None = None, limit: int = 100
    ) -> list[DriveEvent]:
        """The entries newest first (by their time, else when first seen)."""
        where: list[str] = []
        args: list[object] = []
        if drive is not None:
            where.append("drive = ?")
            args.append(drive)
        if since is not None:
            where.append("coalesce(time, seen) >= ?")
            args.append(since)
        sql = f"SELECT {EVENT_COLUMNS} FROM events"
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY coalesce(time, seen) DESC, id DESC LIMIT ?"
        rows = self._query(sql, (*args, limit))
        return [DriveEvent(*row) for row in rows]

    def counts(self) -> Counter[tuple[str, str, str, str, str]]:
        """How many entries are kept by (line, drive, kind, code, text): what
        ``pkwbus_drive_events_total`` starts from."""
        rows = self._query(
            "SELECT line, drive, kind, code, text, count(*) FROM events"
            " GROUP BY line, drive, kind, code, text",
            (),
        )
        return Counter({(r[0], r[1], r[2], r[3], r[4]): r[5] for r in rows})

    def newest(self, drive: str, kind: str) -> DriveEvent | None:
        """The entry of ``kind`` of ``drive`` that pkwbus found last (None: none kept)."""
        rows = self._query(
            f"SELECT {EVENT_COLUMNS} FROM events WHERE drive = ? AND kind = ?"
            " ORDER BY seen DESC, id DESC LIMIT 1",
            (drive, kind),
        )
        return DriveEvent(*rows[0]) if rows else None

    def prune(
        self, drive: str, kinds: Iterable[str], still_held: Iterable[str], before: float
    ) -> int:
        """Drop the entries of ``drive`` of ``kinds`` first seen before ``before`` that its
        log no longer holds; how many. A drive has a log for each kind of entry: one log's
        sweep never drops another's."""
        held, of = list(still_held), list(kinds)
        sql = f"DELETE FROM events WHERE drive = ? AND seen < ? AND kind IN ({_marks(of)})"
        if held:
            sql += f" AND key NOT IN ({_marks(held)})"
        with self._lock:
            try:
                dropped: int = self._db.execute(sql, (drive, before, *of, *held)).rowcount
            except sqlite3.Error as exc:
                raise HistoryError(f"history database {self.path}: {exc}") from None
        if dropped:
            self.changes.changed(EVENTS, [drive])
        return dropped

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def _query(self, sql: str, args: tuple[object, ...]) -> list[Any]:
        with self._lock:
            try:
                return self._db.execute(sql, args).fetchall()
            except sqlite3.Error as exc:
                raise HistoryError(f"history database {self.path}: {exc}") from None


def _marks(values: list[str]) -> str:
    return ", ".join("?" * len(values))
