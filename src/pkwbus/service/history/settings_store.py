"""The drives' settings as swept, and each one's baseline, in the history database (SQLite).

One row per drive and setting (parameter and index): the value the last sweep read (raw
number and value), the baseline it is compared with, since when and by what that baseline
holds (``sweep``: the first sweep; ``write``: a write pkwbus made; ``accepted``: the API
accepted the present values), and since when the value differs from it. One row per drive
for the identity the baseline belongs to and the end of its last complete sweep. Every
store is one synced transaction (:mod:`pkwbus.service.audit.synced`), so a restart
neither forgets a baseline nor reports a change twice.

Thread-safe: the service calls it off the event loop, and opens it there (at the first
load or store, not when it is made). Raises
:class:`~pkwbus.service.history.store.HistoryError` (one line) when the database cannot
be opened or written.
"""

from __future__ import annotations

import asyncio
import json
import logging
import sqlite3
import threading
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from pkwbus.catalog.description import Value
from pkwbus.service.audit.synced import connect_synced
from pkwbus.service.history.store import (
    EVENTS,
    SCHEMA,
    SETTINGS,
    Changes,
    DriveEvent,
    HistoryError,
    insert_events,
    synced_transaction,
)

log = logging.getLogger("pkwbus.service.settings")

__all__ = [
    "SETTINGS_SCHEMA",
    "SettingRow",
    "SettingsStore",
    "SweptDrive",
    "stored_text",
    "stored_value",
]


def stored_text(value: Value | None) -> str | None:
    """A value as a row keeps it (JSON text)."""
    return None if value is None else json.dumps(value)


def stored_value(text: str | None) -> Value | None:
    """A row's value, from the text it keeps (:func:`stored_text`)."""
    return None if text is None else json.loads(text)


SETTINGS_SCHEMA: Final = """
CREATE TABLE IF NOT EXISTS settings (
    drive TEXT NOT NULL,
    pnu INTEGER NOT NULL,
    idx INTEGER NOT NULL,
    parameter TEXT NOT NULL,
    raw INTEGER,
    value TEXT,
    seen REAL,
    baseline_raw INTEGER,
    baseline_value TEXT,
    baseline_since REAL,
    baseline_by TEXT,
    changed_seen REAL,
    PRIMARY KEY (drive, pnu, idx)
);
CREATE TABLE IF NOT EXISTS settings_drives (
    drive TEXT PRIMARY KEY,
    identity TEXT,
    swept REAL
);
"""

_COLUMNS: Final = (
    "drive, pnu, idx, parameter, raw, value, seen, baseline_raw, baseline_value,"
    " baseline_since, baseline_by, changed_seen"
)


@dataclass(slots=True)
class SettingRow:
    """One setting of a drive: the value last read and its baseline (raw numbers compare;
    ``value`` and ``baseline_value`` are as shown, JSON text). ``changed_seen``: since
    when the value differs from the baseline (None: it does not)."""

    drive: str
    pnu: int
    index: int
    parameter: str
    raw: int | None = None
    value: str | None = None
    seen: float | None = None
    baseline_raw: int | None = None
    baseline_value: str | None = None
    baseline_since: float | None = None
    baseline_by: str | None = None
    changed_seen: float | None = None

    @property
    def key(self) -> tuple[int, int]:
        return self.pnu, self.index

    def values(self) -> tuple[Any, ...]:
        return (
            self.drive, self.pnu, self.index, self.parameter, self.raw, self.value, self.seen,
            self.baseline_raw, self.baseline_value, self.baseline_since, self.baseline_by,
            self.changed_seen,
        )  # fmt: skip


@dataclass(slots=True)
class SweptDrive:
    """What is kept of a drive's settings: the identity its baseline belongs to, the end of
    its last complete sweep, and its settings by (PNU, index)."""

    identity: str | None = None
    swept: float | None = None
    rows: dict[tuple[int, int], SettingRow] | None = None


class SettingsStore:
    """The settings' tables of the history database, opened at the first load or store: it
    is made on the event loop (at the start, or by a reload) and used off it. ``changes``:
    where each stored change is counted (the history store's, :class:`Changes`)."""

    def __init__(self, path: str | Path, changes: Changes | None = None) -> None:
        self.path = Path(path)
        self.changes = changes if changes is not None else Changes()
        self._lock = threading.Lock()
        self._opening = threading.Lock()
        self._conn: sqlite3.Connection | None = None
        self._closed = False

    @property
    def _db(self) -> sqlite3.Connection:
        """The connection, opened on first use; :class:`HistoryError` when it cannot be, or
        once the store is closed."""
        conn = self._conn
        if conn is not None:
            return conn
        with self._opening:
            if self._closed:
                raise HistoryError(f"the history database {self.path} is closed")
            if self._conn is None:
                try:
                    self._conn = connect_synced(self.path, SCHEMA + SETTINGS_SCHEMA)
                except (sqlite3.Error, OSError) as exc:
                    raise HistoryError(
                        f"cannot open the history database {self.path}: {exc}"
                    ) from None
            return self._conn

    def load(self, drive: str) -> SweptDrive:
        """What is kept of ``drive`` (empty when nothing is)."""
        found = SweptDrive(rows={})
        with self._lock:
            try:
                head = self._db.execute(
                    "SELECT identity, swept FROM settings_drives WHERE drive = ?", (drive,)
                ).fetchone()
                rows = self._db.execute(
                    f"SELECT {_COLUMNS} FROM settings WHERE drive = ?", (drive,)
                ).fetchall()
            except sqlite3.Error as exc:
                raise HistoryError(f"history database {self.path}: {exc}") from None
        if head is not None:
            found.identity, found.swept = head
        found.rows = {(r[1], r[2]): SettingRow(*r) for r in rows}
        return found

    async def saved(
        self, rows: Iterable[SettingRow], events: Iterable[DriveEvent] = ()
    ) -> list[DriveEvent]:
        """:meth:`save` in a thread, finished even when its caller is cancelled (the
        service stopping): what it raises then, the database closed meanwhile, is logged,
        not left to the loop as a task nobody asked (HistoryError to a caller that waits)."""
        done = asyncio.ensure_future(asyncio.to_thread(self.save, list(rows), list(events)))
        try:
            return await asyncio.shield(done)
        except asyncio.CancelledError:
            done.add_done_callback(_unawaited)
            raise

    def save(
        self, rows: Iterable[SettingRow], events: Iterable[DriveEvent] = ()
    ) -> list[DriveEvent]:
        """Store ``rows`` (each replacing the drive's row of its setting) and the ``events``
        they tell, in one synced transaction: a row flagged changed is never kept without
        its event. The events that were new."""
        sql = f"INSERT OR REPLACE INTO settings ({_COLUMNS}) VALUES ({', '.join('?' * 12)})"
        stored = list(rows)
        with synced_transaction(self._db, self._lock, self.path):
            for row in stored:
                self._db.execute(sql, row.values())
            new = insert_events(self._db, events)
        self.changes.changed(SETTINGS, (row.drive for row in stored))
        self.changes.changed(EVENTS, (e.drive for e in new))
        return new

    def swept(self, drive: str, identity: str | None, when: float | None) -> None:
        """The identity of ``drive``'s baseline and the end of its last complete sweep."""
        sql = "INSERT OR REPLACE INTO settings_drives (drive, identity, swept) VALUES (?, ?, ?)"
        self._write(drive, [(sql, (drive, identity, when))])

    def forget(self, drive: str, identity: str | None) -> None:
        """A new baseline for ``drive``, another drive now (``identity``): its rows go."""
        head = "INSERT OR REPLACE INTO settings_drives (drive, identity, swept) VALUES (?, ?, NULL)"
        self._write(drive, [("DELETE FROM settings WHERE drive = ?", (drive,)),
                            (head, (drive, identity))])  # fmt: skip

    def close(self) -> None:
        with self._lock, self._opening:  # the order of a load's first use
            self._closed = True
            if self._conn is not None:
                self._conn.close()
                self._conn = None

    def _write(self, drive: str, statements: list[tuple[str, tuple[Any, ...]]]) -> None:
        with synced_transaction(self._db, self._lock, self.path):
            for sql, args in statements:
                self._db.execute(sql, args)
        self.changes.changed(SETTINGS, [drive])


def _unawaited(done: asyncio.Future[list[DriveEvent]]) -> None:
    """A save whose caller was cancelled ended: its failure logged (it had no one to
    tell)."""
    if not done.cancelled() and done.exception() is not None:
        log.warning("settings not stored while the service stopped: %s", done.exception())
