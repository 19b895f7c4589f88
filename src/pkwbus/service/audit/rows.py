"""One audit row: :class:`AuditEntry`, the table that keeps it (:data:`SCHEMA`), and its
values as the database keeps them.

Values are kept as JSON (a non-finite number as its name, "nan", which JSON
lacks); a detail or text value is cut to :data:`MAX_TEXT` characters with a
mark saying how long it was.

Raises :class:`ValueError` (a :class:`json.JSONDecodeError`) from
:func:`entry_of_row` only for a value that is not JSON, which the service
never writes.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from typing import Any, Final

__all__ = [
    "COLUMNS",
    "INTERRUPTED",
    "MAX_TEXT",
    "SCHEMA",
    "AuditEntry",
    "as_dict",
    "clip_text",
    "entry_of_row",
    "stored_value",
]

COLUMNS: Final = (
    "id, time, client, token_id, drive, parameter, idx, store, old_value,"
    " new_value, raw_value, outcome, fault, detail"
)
MAX_TEXT: Final = 500  # a detail or value kept in a row, in characters

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
    count: int | None = None  # attempts this row stands for; None for one write attempt


def as_dict(entry: AuditEntry) -> dict[str, Any]:
    return asdict(entry)


def clip_text(text: str | None, limit: int = MAX_TEXT) -> str | None:
    """``text`` cut to ``limit`` characters, with a mark of its length."""
    if text is None or len(text) <= limit:
        return text
    return text[:limit] + f"... ({len(text)} characters)"


def stored_value(value: Any) -> str | None:
    """JSON of a value; a non-finite number is kept as its name ("nan"), which JSON lacks."""
    if value is None:
        return None
    if isinstance(value, float) and not math.isfinite(value):
        return json.dumps(str(value))
    if isinstance(value, str):
        value = clip_text(value)
    return json.dumps(value)


def _value(text: str | None) -> Any:
    return None if text is None else json.loads(text)


def entry_of_row(row: tuple[Any, ...]) -> AuditEntry:
    """The entry of a row selected as :data:`COLUMNS` followed by ``count``."""
    id_, t, client, tok, drive, parameter, idx, store, old, new, raw, outcome, fault = row[:13]
    detail, count = row[13:15]
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
        count=count,
    )
