"""The write audit log: every attempt, refused ones included, in SQLite (WAL mode).

One row per attempt: time, client, token id (a fingerprint, never the
token), drive, parameter, index, old value when read, new value, raw value,
outcome, fault. Requests refused for want of a valid token are the
exception: they are counted in memory, one row per source address and minute
with the number of attempts in ``count`` (their drive and parameter are not
kept), and that row is written once its minute has ended (a timer
:data:`FLUSH_DELAY` after it, or the first refusal of a later minute), when
the log is closed (a clean shutdown), and before an authorised read of the
log (:meth:`AuditLog.latest`). A flood of them costs no write per request: a
killed service loses at most the counts of its last minute or so.

Every other store is committed and synced (``synchronous=FULL``) before the
call returns: the database survives restarts, a killed process and a power
cut. The write-ahead log is checkpointed every :data:`WAL_PAGES` pages and
cut back to :data:`WAL_BYTES` after a checkpoint, so it cannot take the room
of the database on a small disk.
A store that fails raises :class:`AuditError` (one line, no traceback); while
the log cannot record, so does :meth:`AuditLog.refused` (the count is kept
and written once the log records again).

The token fingerprint is an HMAC-SHA256 of the token keyed with a random
secret kept beside the database (``<audit_db>.key``, mode 0600, made on the
first start): the same token has the same id across restarts, and nobody
without the key can test a guess of the token against it.

The key is in :mod:`pkwbus.service.audit.key`, the refusal tallies in
:mod:`pkwbus.service.audit.refusals`, the row and its values in
:mod:`pkwbus.service.audit.rows`, the check of its place in
:mod:`pkwbus.service.audit.place`; this module is the store, and re-exports
their public names. Raises :class:`AuditError` (and :class:`ValueError` from
:meth:`AuditLog.update` for a column it does not complete).
"""

from __future__ import annotations

import contextlib
import logging
import sqlite3
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

from pkwbus.errors import PkwbusError
from pkwbus.service.audit.key import (
    KEY_BYTES,
    TOKEN_ID_HEX,
    fingerprint,
    key_path,
    load_key,
    new_key,
)
from pkwbus.service.audit.place import path_problem
from pkwbus.service.audit.refusals import (
    MAX_SOURCES_PER_MINUTE,
    OTHER_SOURCES,
    RefusalTallies,
    Tally,
    minute_of,
)
from pkwbus.service.audit.rows import (
    COLUMNS,
    INTERRUPTED,
    MAX_TEXT,
    SCHEMA,
    AuditEntry,
    as_dict,
    clip_text,
    entry_of_row,
    stored_value,
)
from pkwbus.service.audit.synced import WAL_BYTES, WAL_PAGES, connect_synced

__all__ = [
    "COLUMNS",
    "FLUSH_DELAY",
    "INTERRUPTED",
    "KEY_BYTES",
    "MAX_SOURCES_PER_MINUTE",
    "MAX_TEXT",
    "OTHER_SOURCES",
    "SCHEMA",
    "TOKEN_ID_HEX",
    "WAL_BYTES",
    "WAL_PAGES",
    "AuditEntry",
    "AuditError",
    "AuditLog",
    "as_dict",
    "key_path",
    "path_problem",
]

log = logging.getLogger("pkwbus.service.audit")  # the name its log lines have always carried

FLUSH_DELAY: Final = 1.0  # seconds after a minute's end before its refusal counts are written


class AuditError(PkwbusError):
    """The audit log cannot be opened or cannot store: the message is one line."""


class AuditLog:
    """A small synchronous store; each store is one short, synced transaction (refusals
    are counted in memory and written by the minute, see the module's text).

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
        self._timer: threading.Timer | None = None
        self._problem: str | None = None  # why the last store failed; None once one succeeds
        self._closed = False
        try:
            if readonly:  # a look at the log: nothing is created or changed
                uri = f"file:{self.path.resolve()}?mode=ro"
                self._db = sqlite3.connect(uri, uri=True, check_same_thread=False)
                self._has_count = "count" in self._columns()
                return
            memory = str(path) == ":memory:"
            self._db = connect_synced(path, SCHEMA)
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
        """Count a request refused for want of a valid token, in memory: one row per
        address and minute, written once the minute has ended.

        Raises :class:`AuditError` when the counts of an ended minute cannot be written,
        or while the log cannot record: the count is kept all the same."""
        now = self.clock()
        with self._lock:
            self._refusals.count(now, client, kind)
            self._give_up_locked()
            if self._timer is None and not self._closed:
                self._arm_locked(now)
            if self._problem is not None:  # the timer tries again, or a store that succeeds
                raise AuditError(self._problem)
            self._flush_locked(self._refusals.due(now), now)  # a minute has ended

    def flush(self) -> int:
        """Write the refusal counts of the minutes that have ended; returns how many
        refusals that adds. :class:`AuditError` when they cannot be written (kept)."""
        now = self.clock()
        with self._lock:
            due = self._refusals.due(now)
            added = sum(t.count - t.saved for t in due)
            self._flush_locked(due, now)
            return added

    def probe(self) -> None:
        """A small committed store, to learn whether the log can record again."""
        self._store("INSERT OR REPLACE INTO probe (id, time) VALUES (1, ?)", (self.clock(),))

    def latest(self, limit: int = 100) -> list[AuditEntry]:
        """The newest ``limit`` rows by time, the refusal counts not yet written written
        first (a minute's refusal row is written after it, so its id is a later one)."""
        count = "count" if self._has_count else "NULL"
        try:
            with self._lock:
                with contextlib.suppress(AuditError):  # counts not written stay counted
                    self._flush_locked(self._refusals.due(), self.clock())
                rows = self._db.execute(
                    f"SELECT {COLUMNS}, {count} FROM writes ORDER BY time DESC, id DESC LIMIT ?",
                    (limit,),
                ).fetchall()
        except sqlite3.Error as exc:
            raise AuditError(f"cannot read the audit log {self.path}: {_reason(exc)}") from None
        return [entry_of_row(r) for r in rows]

    def close(self) -> None:
        """Write the refusal counts not yet written (a clean shutdown loses none), close."""
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            if not self._closed:
                self._closed = True
                pending = self._refusals.pending()
                try:
                    self._flush_locked(self._refusals.due(), self.clock())
                except AuditError as exc:
                    log.error(
                        "audit log: the counts of %d refused request(s) cannot be stored: %s",
                        pending,
                        exc,
                    )
            self._db.close()

    # ----------------------------------------------------------- helpers

    def _store(self, sql: str, args: tuple[Any, ...]) -> sqlite3.Cursor:
        with self._lock:
            try:
                cur = self._execute_locked(sql, args)
            except AuditError as exc:
                self._problem = str(exc)
                raise
            self._problem = None
            return cur

    def _flush_locked(self, tallies: list[Tally], now: float) -> None:
        """Write ``tallies`` in one synced transaction; :class:`AuditError` (nothing
        written, the tallies kept) when it fails."""
        if not tallies:
            return
        rows: list[int] = []
        try:
            self._db.execute("BEGIN IMMEDIATE")
            for tally in tallies:
                if tally.row is None:
                    cur = self._db.execute(
                        "INSERT INTO writes (time, client, drive, parameter, outcome, detail,"
                        " count) VALUES (?, ?, '', '', 'refused', ?, ?)",
                        (tally.time, tally.client, tally.detail, tally.count),
                    )
                    assert cur.lastrowid is not None
                    rows.append(cur.lastrowid)
                else:
                    self._db.execute(
                        "UPDATE writes SET count = ?, detail = ? WHERE id = ?",
                        (tally.count, tally.detail, tally.row),
                    )
                    rows.append(tally.row)
            self._db.execute("COMMIT")
        except sqlite3.Error as exc:
            with contextlib.suppress(sqlite3.Error):
                self._db.execute("ROLLBACK")
            self._problem = _reason(exc)
            raise AuditError(self._problem) from None
        self._problem = None
        self._refusals.written(tallies, rows, now)

    def _arm_locked(self, now: float) -> None:
        """A timer that writes the counts of this minute just after it ends."""
        delay = min(60.0, max(0.0, (minute_of(now) + 1) * 60 - now)) + FLUSH_DELAY
        self._timer = threading.Timer(delay, self._on_timer)
        self._timer.name = "pkwbus-audit-refusals"
        self._timer.daemon = True
        self._timer.start()

    def _on_timer(self) -> None:
        with self._lock:
            self._timer = None
            if self._closed:
                return
            now = self.clock()
            self._give_up_locked()
            due = self._refusals.due(now)
            failing = self._problem is not None
            try:
                self._flush_locked(due, now)
            except AuditError as exc:
                if not failing:  # told when it starts failing, not every minute
                    count = sum(t.count - t.saved for t in due)
                    log.warning(
                        "audit log cannot store the counts of %d refused request(s): %s;"
                        " kept, tried again in a minute",
                        count,
                        exc,
                    )
            if self._refusals.pending():
                self._arm_locked(now)

    def _give_up_locked(self) -> None:
        dropped = self._refusals.give_up()
        if dropped:
            log.error(
                "audit log: the counts of %d refused request(s) from %s on could not be"
                " stored for %d minutes and are given up",
                sum(t.count - t.saved for t in dropped),
                time.strftime("%Y-%m-%d %H:%M %z", time.localtime(dropped[0].minute * 60)),
                self._refusals.max_minutes,
            )

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
