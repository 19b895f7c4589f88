"""The write audit log: every attempt, refused ones included, in SQLite (WAL mode).

One row per attempt: time, client, token identity (a fingerprint, never the
token), drive, parameter, index, old value when read, new value, raw value,
outcome, fault. The database survives restarts and a killed process.
"""

from __future__ import annotations

import hashlib
import json
import math
import sqlite3
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

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
    detail      TEXT
);
CREATE INDEX IF NOT EXISTS writes_time ON writes (time);
"""


def token_id(token: str) -> str:
    """A short fingerprint that names a token without revealing it."""
    return "sha256:" + hashlib.sha256(token.encode()).hexdigest()[:12]


@dataclass
class AuditEntry:
    client: str
    drive: str
    parameter: str
    index: int
    outcome: str  # ok, rejected, timeout, cancelled, refused, invalid, pending, mismatch
    token_id: str | None = None
    store: str | None = None
    old_value: Any = None
    new_value: Any = None
    raw_value: int | None = None
    fault: int | None = None
    detail: str | None = None
    time: float = 0.0
    id: int | None = None


class AuditLog:
    """A small synchronous store; each call is one short transaction."""

    def __init__(self, path: str | Path, *, readonly: bool = False) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()
        if readonly:  # a look at the log: nothing is created or changed
            uri = f"file:{self.path.resolve()}?mode=ro"
            self._db = sqlite3.connect(uri, uri=True, check_same_thread=False)
            return
        if str(path) != ":memory:":
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self._db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.executescript(SCHEMA)

    def close_interrupted(self) -> int:
        """Rows a killed service left 'pending': their outcome is unknown. Returns how many."""
        with self._lock:
            cur = self._db.execute(
                "UPDATE writes SET outcome = 'interrupted', detail = 'the service stopped"
                " before the answer; the drive may have applied the write'"
                " WHERE outcome = 'pending'"
            )
        return cur.rowcount

    def record(self, entry: AuditEntry) -> int:
        """Insert an attempt (outcome may be 'pending'); returns its row id."""
        entry.time = entry.time or time.time()
        with self._lock:
            cur = self._db.execute(
                "INSERT INTO writes (time, client, token_id, drive, parameter, idx, store,"
                " old_value, new_value, raw_value, outcome, fault, detail)"
                " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    entry.time,
                    entry.client,
                    entry.token_id,
                    entry.drive,
                    entry.parameter,
                    entry.index,
                    entry.store,
                    _text(entry.old_value),
                    _text(entry.new_value),
                    entry.raw_value,
                    entry.outcome,
                    entry.fault,
                    entry.detail,
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
        values = [_text(v) if k in ("old_value", "new_value") else v for k, v in fields.items()]
        with self._lock:
            self._db.execute(f"UPDATE writes SET {cols} WHERE id = ?", (*values, row))

    def latest(self, limit: int = 100) -> list[AuditEntry]:
        with self._lock:
            rows = self._db.execute(
                "SELECT id, time, client, token_id, drive, parameter, idx, store, old_value,"
                " new_value, raw_value, outcome, fault, detail FROM writes"
                " ORDER BY id DESC LIMIT ?",
                (limit,),
            ).fetchall()
        return [_entry(r) for r in rows]

    def close(self) -> None:
        with self._lock:
            self._db.close()


def _text(value: Any) -> str | None:
    """JSON of a value; a non-finite number is kept as its name ("nan"), which JSON lacks."""
    if value is None:
        return None
    if isinstance(value, float) and not math.isfinite(value):
        return json.dumps(str(value))
    return json.dumps(value)


def _value(text: str | None) -> Any:
    return None if text is None else json.loads(text)


def _entry(row: tuple[Any, ...]) -> AuditEntry:
    (id_, t, client, tok, drive, parameter, idx, store, old, new, raw, outcome, fault, detail) = row
    return AuditEntry(
        client=client,
        drive=drive,
        parameter=parameter,
        index=idx,
        outcome=outcome,
        token_id=tok,
        store=store,
        old_value=_value(old),
        new_value=_value(new),
        raw_value=raw,
        fault=fault,
        detail=detail,
        time=t,
        id=id_,
    )


def as_dict(entry: AuditEntry) -> dict[str, Any]:
    return asdict(entry)
