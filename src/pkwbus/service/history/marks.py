"""A line's marks as a document (:mod:`pkwbus.service.assembly.line_marks`): read from the
history database, merged into it, encoded under a bound.

Encoded whole (:func:`encode`), or made again from what the last one was made of
(:func:`make`): a part - the line's log entries, its drives' settings - is read and encoded
again only when the history counted a change of it since
(:class:`~pkwbus.service.history.store.Changes`); the rest is joined as text. Either way the
same bytes: compact JSON, keys in the document's order, the oldest log entries left out
past the bound by one rule (:func:`fit`).
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import accumulate
from pathlib import Path
from typing import Any, Final

from pkwbus.service.audit.synced import connect_synced
from pkwbus.service.history.settings_store import SETTINGS_SCHEMA
from pkwbus.service.history.store import EVENT_COLUMNS, SCHEMA

__all__ = [
    "Made",
    "dumps",
    "encode",
    "export",
    "fit",
    "make",
    "merge",
    "read_events",
    "read_settings",
]

_SETTINGS: Final = (
    "drive, pnu, idx, parameter, raw, value, seen, baseline_raw, baseline_value,"
    " baseline_since, baseline_by, changed_seen"
)


def _marks(values: Sequence[str]) -> str:
    return ", ".join("?" * len(values))


def _open(path: Path) -> sqlite3.Connection:
    return connect_synced(path, SCHEMA + SETTINGS_SCHEMA)


def read_events(db: sqlite3.Connection, drives: Sequence[str]) -> list[list[Any]]:
    """The log entries ``db`` keeps of ``drives``, oldest first."""
    rows = db.execute(
        f"SELECT {EVENT_COLUMNS} FROM events WHERE drive IN ({_marks(drives)}) ORDER BY seen, id",
        tuple(drives),
    ).fetchall()
    return [list(r) for r in rows]


def read_settings(db: sqlite3.Connection, drives: Sequence[str]) -> tuple[list[Any], list[Any]]:
    """The settings ``db`` keeps of ``drives`` (baselines included), and their last sweeps."""
    of = _marks(drives)
    settings = db.execute(
        f"SELECT {_SETTINGS} FROM settings WHERE drive IN ({of}) ORDER BY drive, pnu, idx",
        tuple(drives),
    ).fetchall()
    swept = db.execute(
        f"SELECT drive, identity, swept FROM settings_drives WHERE drive IN ({of}) ORDER BY drive",
        tuple(drives),
    ).fetchall()
    return [list(r) for r in settings], [list(r) for r in swept]


def export(path: Path, drives: Sequence[str]) -> dict[str, Any]:
    """The events and settings the database ``path`` keeps of ``drives`` (events oldest
    first)."""
    db = _open(path)
    try:
        events = read_events(db, drives)
        settings, swept = read_settings(db, drives)
    finally:
        db.close()
    return {"events": events, "settings": settings, "swept": swept}


def _latest(db: sqlite3.Connection, drive: str) -> float | None:
    """When the database last saw ``drive``'s settings (sweep or baseline)."""
    row = db.execute(
        "SELECT max(coalesce((SELECT swept FROM settings_drives WHERE drive = ?), 0),"
        " coalesce((SELECT max(max(coalesce(seen, 0), coalesce(baseline_since, 0)))"
        " FROM settings WHERE drive = ?), 0))",
        (drive, drive),
    ).fetchone()
    return row[0] or None


def _latest_of(doc: Mapping[str, Any], drive: str) -> float:
    times = [r[2] or 0 for r in doc.get("swept", []) if r[0] == drive]
    for r in doc.get("settings", []):
        if r[0] == drive:
            times += [r[6] or 0, r[9] or 0]
    return max(times, default=0)


def merge(path: Path, doc: Mapping[str, Any]) -> int:
    """Merge the line's document ``doc`` into the database ``path`` (the rule in
    :mod:`.line_marks`), in one transaction; how many log entries were new here."""
    db = _open(path)
    try:
        with db:
            added = 0
            row_of = f"INSERT OR IGNORE INTO events ({EVENT_COLUMNS}) VALUES ({_marks('?' * 12)})"
            for event in doc.get("events", []):
                added += db.execute(row_of, tuple(event)).rowcount
            drives = {r[0] for r in doc.get("swept", [])} | {r[0] for r in doc.get("settings", [])}
            for drive in sorted(drives):
                local = _latest(db, drive)
                if local is not None and local >= _latest_of(doc, drive):
                    continue  # this instance's view is as new: it stays
                db.execute("DELETE FROM settings WHERE drive = ?", (drive,))
                db.execute("DELETE FROM settings_drives WHERE drive = ?", (drive,))
                for r in doc.get("settings", []):
                    if r[0] == drive:
                        db.execute(
                            f"INSERT INTO settings ({_SETTINGS}) VALUES ({_marks('?' * 12)})",
                            tuple(r),
                        )
                for r in doc.get("swept", []):
                    if r[0] == drive:
                        db.execute(
                            "INSERT INTO settings_drives (drive, identity, swept) VALUES (?, ?, ?)",
                            tuple(r),
                        )
    finally:
        db.close()
    return added


def dumps(value: Any) -> str:
    """``value`` as compact JSON (ASCII: as many bytes as characters)."""
    return json.dumps(value, separators=(",", ":"))


def _object(parts: Sequence[tuple[str, str]]) -> str:
    """The members of a JSON object, each key with its value's JSON text."""
    return ",".join(f"{dumps(key)}:{text}" for key, text in parts)


def fit(
    before: Sequence[tuple[str, str]],
    events: Sequence[str],
    after: Sequence[tuple[str, str]],
    limit: int,
) -> tuple[bytes, int]:
    """The document of the members ``before``, ``"events"`` (each entry's JSON text,
    oldest first) and ``after``, under ``limit`` bytes; how many of its oldest entries
    were left out to keep it there (ValueError: too big without any). The sizes are
    counted, the text made once."""
    head = "{" + _object(before) + ("," if before else "") + '"events":['
    tail = "]" + ("," if after else "") + _object(after) + "}"
    left = list(accumulate(reversed([len(e) + 1 for e in events]), initial=0))[::-1]
    n, dropped = len(events), 0
    while True:
        size = len(head) + len(tail) + max(0, left[dropped] - 1)  # a comma between two
        if size <= limit:
            return (head + ",".join(events[dropped:]) + tail).encode(), dropped
        if dropped >= n:
            raise ValueError(f"a line's marks take {size} bytes without log entries")
        # Drop about the share over the limit, at least one.
        over = (size - limit) / size
        dropped = min(n, dropped + max(1, int((n - dropped) * over) + 1))


def encode(doc: Mapping[str, Any], limit: int) -> tuple[bytes, int]:
    """The document as compact JSON under ``limit`` bytes, and how many of its oldest log
    entries were left out to keep it there (settings and maintenance are never left
    out; a document too big without any entries is refused with ValueError)."""
    keys = list(doc)
    at = keys.index("events") if "events" in doc else len(keys)
    before = [(k, dumps(doc[k])) for k in keys[:at]]
    after = [(k, dumps(doc[k])) for k in keys[at + 1 :]]
    return fit(before, [dumps(e) for e in doc.get("events", [])], after, limit)


@dataclass(frozen=True, slots=True)
class Made:
    """What a line's document was last made of: its drives, its log entries' JSON text
    (oldest first) and its settings' (``settings`` and ``swept``), each with the count of
    the history's changes it was read at (None: not known, read again)."""

    drives: tuple[str, ...]
    events_at: int | None
    events: tuple[str, ...]
    settings_at: int | None
    settings: tuple[tuple[str, str], ...]


def make(
    path: Path | None,
    drives: tuple[str, ...],
    counts: tuple[int | None, int | None],
    last: Made | None,
    extra: Sequence[tuple[str, str]],
    limit: int,
) -> tuple[Made, bytes, int]:
    """A line's document (of :func:`export` of ``drives``, then ``extra``'s members) made
    again from ``last``: the log entries read and encoded again only when their count
    (``counts``: entries, settings) moved since, the settings likewise. What it was made
    of, its bytes, and how many entries were left out (:func:`fit`). In a thread."""
    if path is None or not drives:
        made = Made(drives, None, (), None, ())
        return (made, *fit(extra, (), (), limit))
    kept = last if last is not None and last.drives == drives else None
    events_at, settings_at = counts
    db: sqlite3.Connection | None = None
    try:
        if kept is not None and events_at is not None and kept.events_at == events_at:
            events = kept.events
        else:
            db = _open(path)
            events = tuple(dumps(e) for e in read_events(db, drives))
        if kept is not None and settings_at is not None and kept.settings_at == settings_at:
            settings = kept.settings
        else:
            db = db or _open(path)
            rows, swept = read_settings(db, drives)
            settings = (("settings", dumps(rows)), ("swept", dumps(swept)))
    finally:
        if db is not None:
            db.close()
    made = Made(drives, events_at, events, settings_at, settings)
    return (made, *fit((), events, (*settings, *extra), limit))
