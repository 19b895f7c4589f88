"""The write audit log: every attempt, refused ones included, in SQLite (WAL mode).

One row per attempt: time, client, token identity (a fingerprint, never the
token), drive, parameter, index, old value when read, new value, raw value,
outcome, fault. Requests refused for want of a valid token are the
exception: they are counted, one row per source address and minute with the
number of attempts in ``count`` (their drive and parameter are not kept), so
a flood of them cannot grow the database.

Every store is committed and synced (``synchronous=FULL``) before the call
returns: the database survives restarts, a killed process and a power cut.
The counts of refused requests are committed without a sync of their own
(they reach the disk with the next synced store or checkpoint): a flood of
refusals costs no disk flush per request.
A store that fails raises :class:`AuditError` (one line, no traceback).


The token fingerprint is an HMAC-SHA256 of the token keyed with a random
secret kept beside the database (``<audit_db>.key``, mode 0600, made on the
first start): the same token has the same id across restarts, and nobody
without the key can test a guess of the token against it.

The key is in :mod:`pkwbus.service.audit_key`, the refusal tallies in
:mod:`pkwbus.service.audit_refusals`, the row and its values in
:mod:`pkwbus.service.audit_rows`; this module is the store, and re-exports
their public names. Raises :class:`AuditError` (and :class:`ValueError` from
:meth:`AuditLog.update` for a column it does not complete).
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import stat
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

from pkwbus.service.audit_key import (
    KEY_BYTES,
    TOKEN_ID_HEX,
    fingerprint,
    key_path,
    load_key,
    new_key,
)
from pkwbus.service.audit_refusals import MAX_SOURCES_PER_MINUTE, OTHER_SOURCES, RefusalTallies
from pkwbus.service.audit_rows import (
    COLUMNS,
    MAX_TEXT,
    AuditEntry,
    as_dict,
    clip_text,
    entry_of_row,
    stored_value,
)

__all__ = [
    "COLUMNS",
    "INTERRUPTED",
    "KEY_BYTES",
    "MAX_SOURCES_PER_MINUTE",
    "MAX_TEXT",
    "OTHER_SOURCES",
    "SCHEMA",
    "TOKEN_ID_HEX",
    "AuditEntry",
    "AuditError",
    "AuditLog",
    "as_dict",
    "key_path",
    "path_problem",
]

SCHEMA = """
CREATE TABLE IF NOT EXISTS writes (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    time        REAL    NOT NULL,
    client      TEXT    NOT NULL,
    token_id    TEXT,
    drive       TEXT    NOT NULL,
    parameter   TEXT    NOT NULL,
    idx         INTEGER NOT NULL DEFAULT 0,
    store       TEXT,
    old_value   TEXT,
    new_value   TEXT,
    raw_value   INTEGER,
    outcome     TEXT    NOT NULL,
    fault       INTEGER,
    detail      TEXT,
    count       INTEGER
);
CREATE INDEX IF NOT EXISTS writes_time ON writes (time);
CREATE TABLE IF NOT EXISTS probe (id INTEGER PRIMARY KEY CHECK (id = 1), time REAL NOT NULL);
"""

INTERRUPTED: Final = (
    "no outcome was recorded (the service stopped before the answer, or could not"
    " store it); the drive may have applied the write"
)


class AuditError(Exception):
    """The audit log cannot be opened or cannot store: the message is one line."""


def path_problem(db: Path) -> str | None:
    """Why ``db`` cannot be the audit database on this machine, or None.

    A file there must be a regular, writable file; otherwise the nearest existing
    directory above it must be writable (the service makes the missing ones).
    """
    if str(db) == ":memory:":
        return None
    for path, what in ((db, "the audit database"), (key_path(db), "its key file")):
        try:
            mode = path.stat().st_mode
        except (FileNotFoundError, NotADirectoryError):
            continue
        except OSError as exc:
            return f"{path}: {exc.strerror or exc}"
        if stat.S_ISDIR(mode):
            return f"{path} is a directory, not a file for {what}"
        if not stat.S_ISREG(mode):
            return f"{path} is not a regular file (a device or pipe cannot hold {what})"
        if not os.access(path, os.R_OK | os.W_OK):
            return f"{path} is not writable (read-only file system or permissions)"
    parent = db.parent
    while not parent.exists():
        if parent.is_symlink() or parent == parent.parent:
            return f"{db.parent} cannot be created"
        parent = parent.parent
    if not parent.is_dir():
        return f"{parent} is not a directory: {db.parent} cannot be created"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"{parent} is not writable (read-only file system or permissions)"
    return None


class AuditLog:
    """A small synchronous store; each call is one short, synced transaction.

    Thread-safe: the service calls it from worker threads, off the event loop.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        readonly: bool = False,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.path = Path(path)
        self.clock = clock
        self._lock = threading.Lock()
        self._key: bytes | None = None
        self._refusals = RefusalTallies()
        try:
            if readonly:  # a look at the log: nothing is created or changed
                uri = f"file:{self.path.resolve()}?mode=ro"
                self._db = sqlite3.connect(uri, uri=True, check_same_thread=False)
                self._has_count = "count" in self._columns()
                return
            memory = str(path) == ":memory:"
            if not memory:
                self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.executescript(SCHEMA)
            if "count" not in self._columns():  # a database of an earlier version
                self._db.execute("ALTER TABLE writes ADD COLUMN count INTEGER")
            self._has_count = True
            self._key = new_key() if memory else load_key(self.path)
        except (sqlite3.Error, OSError) as exc:
            with contextlib.suppress(Exception):
                self._db.close()
            raise AuditError(f"cannot open the audit log {self.path}: {_reason(exc)}") from None

    def _columns(self) -> set[str]:
        return {row[1] for row in self._db.execute("PRAGMA table_info(writes)")}

    def token_id(self, token: str) -> str:
        """The token's fingerprint: HMAC-SHA256 keyed with this installation's secret."""
        if self._key is None:
            raise AuditError("a read-only look at the audit log has no key")
        return fingerprint(self._key, token)

    def close_interrupted(self) -> int:
        """Rows a killed service left 'pending': their outcome is unknown. Returns how many."""
        cur = self._store(
            "UPDATE writes SET outcome = 'interrupted', detail = ? WHERE outcome = 'pending'",
            (INTERRUPTED,),
        )
        return cur.rowcount

    def record(self, entry: AuditEntry) -> int:
        """Insert an attempt (outcome may be 'pending'), committed; returns its row id."""
        entry.time = entry.time or self.clock()
        cur = self._store(
            "INSERT INTO writes (time, client, token_id, drive, parameter, idx, store,"
            " old_value, new_value, raw_value, outcome, fault, detail, count)"
            " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                entry.time,
                entry.client,
                entry.token_id,
                entry.drive,
                entry.parameter,
                entry.index,
                entry.store,
                stored_value(entry.old_value),
                stored_value(entry.new_value),
                entry.raw_value,
                entry.outcome,
                entry.fault,
                clip_text(entry.detail),
                entry.count,
            ),
        )
        row = cur.lastrowid
        assert row is not None
        entry.id = row
        return row

    def update(self, row: int, **fields: Any) -> None:
        """Complete a row: outcome, fault, old value, detail."""
        allowed = {"outcome", "fault", "old_value", "detail", "raw_value", "new_value"}
        unknown = set(fields) - allowed
        if unknown:
            raise ValueError(f"cannot update {sorted(unknown)}")
        cols = ", ".join(f"{k} = ?" for k in fields)
        values = [_column_value(k, v) for k, v in fields.items()]
        self._store(f"UPDATE writes SET {cols} WHERE id = ?", (*values, row))

    def refused(self, client: str, kind: str) -> None:
        """Count a request refused for want of a valid token: one row per address and
        minute, its ``count`` raised with each further attempt."""
        now = self.clock()
        with self._lock:
            refusal = self._refusals.next(now, client, kind)
            if refusal.row is None:
                cur = self._unsynced_locked(
                    "INSERT INTO writes (time, client, drive, parameter, outcome, detail, count)"
                    " VALUES (?, ?, '', '', 'refused', ?, 1)",
                    (now, refusal.client, refusal.detail),
                )
                assert cur.lastrowid is not None
                self._refusals.stored(refusal, cur.lastrowid)
            else:
                self._unsynced_locked(
                    "UPDATE writes SET count = count + 1, detail = ? WHERE id = ?",
                    (refusal.detail, refusal.row),
                )
                self._refusals.stored(refusal, refusal.row)

    def probe(self) -> None:
        """A small committed store, to learn whether the log can record again."""
        self._store("INSERT OR REPLACE INTO probe (id, time) VALUES (1, ?)", (self.clock(),))

    def latest(self, limit: int = 100) -> list[AuditEntry]:
        count = "count" if self._has_count else "NULL"
        try:
            with self._lock:
                rows = self._db.execute(
                    f"SELECT {COLUMNS}, {count} FROM writes ORDER BY id DESC LIMIT ?", (limit,)
                ).fetchall()
        except sqlite3.Error as exc:
            raise AuditError(f"cannot read the audit log {self.path}: {_reason(exc)}") from None
        return [entry_of_row(r) for r in rows]

    def close(self) -> None:
        with self._lock:
            self._db.close()

    # ----------------------------------------------------------- helpers

    def _store(self, sql: str, args: tuple[Any, ...]) -> sqlite3.Cursor:
        with self._lock:
            return self._execute_locked(sql, args)

    def _unsynced_locked(self, sql: str, args: tuple[Any, ...]) -> sqlite3.Cursor:
        """Commit without waiting for the disk (WAL with synchronous=NORMAL)."""
        self._execute_locked("PRAGMA synchronous=NORMAL", ())
        try:
            return self._execute_locked(sql, args)
        finally:
            self._execute_locked("PRAGMA synchronous=FULL", ())

    def _execute_locked(self, sql: str, args: tuple[Any, ...]) -> sqlite3.Cursor:
        try:
            return self._db.execute(sql, args)
        except sqlite3.Error as exc:
            raise AuditError(_reason(exc)) from None


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        where = f"{exc.filename}: " if exc.filename else ""
        return f"{where}{exc.strerror}"
    return str(exc) or type(exc).__name__


def _column_value(column: str, value: Any) -> Any:
    if column in ("old_value", "new_value"):
        return stored_value(value)
    return clip_text(value) if column == "detail" else value
