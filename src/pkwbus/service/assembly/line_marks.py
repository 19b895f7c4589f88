"""A line's drive-memory marks carried across a move in hot standby (issue "hot standby",
item 5): the next master of a line neither tells the drives' old log entries again nor
loses a settings baseline nor forgets a drive in maintenance.

One JSON document per line, the mark ``memory`` (:class:`~pkwbus.service.standby.Marks`):
``events`` (the log entries kept of the line's drives, as the history database keeps
them: what was told), ``settings`` and ``swept`` (each drive's settings, baselines
included, and the identity and end of its last sweep), ``maintenance`` (the drives in
maintenance and why), ``book`` (the describe book: drives' descriptions by model, shared
by the instance's lines, so it is carried whole).

Merge rule, when this instance wins the line (before its watchers tell anything):

- a log entry is added when the local database does not hold it (by drive and key); one
  held locally stays as this instance saw it;
- a drive's settings are taken whole from etcd when etcd's last sweep (or baseline) of
  it is newer than the local one, or the local database has none: etcd wins for what
  this instance did not see itself, the newer view of a drive wins otherwise;
- a drive etcd says is in maintenance is put in maintenance here (since the move);
- a describe book entry is added when this instance has none for that model and
  parameter, or one with fewer elements read; its own stay.

Bound: a document stays under :data:`MAX_MARK_BYTES` (etcd takes 1.5 MiB a request); past
it the oldest log entries are left out (logged once a line): those could be told again.
Written while the line is held, every :data:`WRITE_EVERY` seconds when it changed, off
the loop (the database read in a thread) and never on the exchange path; a put that
fails is tried again at the next turn, logged once until one succeeds.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import sqlite3
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import Any, Final, Protocol

from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.service.audit.synced import connect_synced
from pkwbus.service.history.settings_store import SETTINGS_SCHEMA
from pkwbus.service.history.store import EVENT_COLUMNS, SCHEMA
from pkwbus.service.runtime import Runtime

__all__ = ["MARK", "MAX_MARK_BYTES", "WRITE_EVERY", "LineMarks", "encode", "export", "merge"]

log = logging.getLogger("pkwbus.service.standby")

MARK: Final = "memory"
MAX_MARK_BYTES: Final = 1_000_000
WRITE_EVERY: Final = 2.0

_SETTINGS: Final = (
    "drive, pnu, idx, parameter, raw, value, seen, baseline_raw, baseline_value,"
    " baseline_since, baseline_by, changed_seen"
)


class Saved(Protocol):
    """Where the describe book is kept on disk (:class:`.description_file.DescriptionFile`)."""

    def save(self) -> None: ...


class MarkStore(Protocol):
    """What is asked of :class:`~pkwbus.service.standby.Marks`."""

    async def get(self, line: str, name: str) -> bytes | None: ...
    async def put(self, line: str, name: str, value: bytes) -> bool: ...


def _marks(values: Sequence[str]) -> str:
    return ", ".join("?" * len(values))


def _open(path: Path) -> sqlite3.Connection:
    return connect_synced(path, SCHEMA + SETTINGS_SCHEMA)


def export(path: Path, drives: Sequence[str]) -> dict[str, Any]:
    """The events and settings the database ``path`` keeps of ``drives`` (events oldest
    first)."""
    db = _open(path)
    try:
        of = _marks(drives)
        events = db.execute(
            f"SELECT {EVENT_COLUMNS} FROM events WHERE drive IN ({of}) ORDER BY seen, id",
            tuple(drives),
        ).fetchall()
        settings = db.execute(
            f"SELECT {_SETTINGS} FROM settings WHERE drive IN ({of}) ORDER BY drive, pnu, idx",
            tuple(drives),
        ).fetchall()
        swept = db.execute(
            f"SELECT drive, identity, swept FROM settings_drives WHERE drive IN ({of})"
            " ORDER BY drive",
            tuple(drives),
        ).fetchall()
    finally:
        db.close()
    return {
        "events": [list(r) for r in events],
        "settings": [list(r) for r in settings],
        "swept": [list(r) for r in swept],
    }


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
    """Merge the line's document ``doc`` into the database ``path`` (the rule in the
    module's docstring), in one transaction; how many log entries were new here."""
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


def encode(doc: Mapping[str, Any], limit: int = MAX_MARK_BYTES) -> tuple[bytes, int]:
    """The document as compact JSON under ``limit`` bytes, and how many of its oldest log
    entries were left out to keep it there (settings and maintenance are never left
    out; a document too big without any entries is refused with ValueError)."""
    events = list(doc.get("events", []))
    dropped = 0
    while True:
        text = json.dumps({**doc, "events": events[dropped:]}, separators=(",", ":"))
        data = text.encode()
        if len(data) <= limit:
            return data, dropped
        if dropped >= len(events):
            raise ValueError(f"a line's marks take {len(data)} bytes without log entries")
        # Drop about the share over the limit, at least one.
        over = (len(data) - limit) / len(data)
        dropped = min(len(events), dropped + max(1, int((len(events) - dropped) * over) + 1))


class LineMarks:
    """The marks of the lines this instance masters: loaded when it wins one, written
    while it holds it. ``history``: the history database (None: no drive memory kept,
    only maintenance is carried); ``drives_of``: the drives of a line."""

    def __init__(
        self,
        marks: MarkStore,
        runtime: Runtime,
        history: Path | None,
        drives_of: Callable[[str], Sequence[str]],
        every: float = WRITE_EVERY,
        limit: int = MAX_MARK_BYTES,
        book: DescriptionBook | None = None,
        saved: Saved | None = None,
    ) -> None:
        self.marks = marks
        self.runtime = runtime
        self.history = history
        self.drives_of = drives_of
        self.every = every
        self.limit = limit
        self.book = book
        self.saved = saved
        self._writers: dict[str, asyncio.Task[None]] = {}
        self._written: dict[str, bytes] = {}
        self._failing: set[str] = set()
        self._cut: set[str] = set()

    async def load(self, line: str) -> dict[str, str]:
        """Merge ``line``'s marks into the local database; the drives in maintenance and
        why (to put them in maintenance once the line runs). Nothing when etcd does not
        answer (logged: old log entries may then be told again)."""
        try:
            data = await self.marks.get(line, MARK)
        except Exception as exc:  # EtcdError: unknown, start with what is kept here
            log.warning("line %s: its marks could not be read from etcd: %s", line, exc)
            return {}
        if data is None:
            return {}
        try:
            doc = json.loads(data)
            if not isinstance(doc, dict):
                raise ValueError("not an object")
            if self.history is not None:
                added = await asyncio.to_thread(merge, self.history, doc)
                log.info("line %s: its marks merged, %d log entries known from etcd", line, added)
            self._merge_book(doc.get("book"))
            kept = doc.get("maintenance", {})
            return {str(k): str(v) for k, v in kept.items()} if isinstance(kept, dict) else {}
        except (ValueError, TypeError, IndexError, sqlite3.Error) as exc:
            log.warning("line %s: its marks in etcd are unusable, left aside: %s", line, exc)
            return {}

    def _merge_book(self, found: object) -> None:
        """The describe book's entries this instance lacks (or has with fewer elements read)
        taken from ``found`` (:meth:`DescriptionBook.to_json`); ValueError when unusable."""
        if self.book is None or found is None:
            return
        added = 0
        for identity, pnus in DescriptionBook.from_json(found).entries.items():
            for pnu, (description, read) in pnus.items():
                here = self.book.entries.get(identity, {}).get(pnu)
                if here is None or not read <= here[1]:
                    self.book.put(identity, pnu, description, read)
                    added += 1
        if added and self.saved is not None:
            self.saved.save()

    def maintained(self, line: str, kept: Mapping[str, str]) -> None:
        """Put the drives of ``kept`` in maintenance on ``line``'s runner (once it runs)."""
        runner = self.runtime.runners.get(line)
        if runner is None:
            return
        for drive, reason in kept.items():
            if drive in self.drives_of(line):
                with contextlib.suppress(KeyError):
                    runner.maintenance(drive, True, reason)

    def hold(self, line: str) -> None:
        """Write ``line``'s marks while it is held."""
        if line not in self._writers:
            self._writers[line] = asyncio.create_task(self._write_on(line), name=f"marks {line}")

    async def release(self, line: str, *, flush: bool) -> None:
        """Stop writing ``line``'s marks; ``flush``: written once more first (the lease is
        still held: the service stops)."""
        task = self._writers.pop(line, None)
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        if flush:
            await self.write(line)
        self._written.pop(line, None)

    async def keep_only(self, lines: Collection[str]) -> None:
        """A reload removed the other lines: their marks are no longer written."""
        for line in [name for name in self._writers if name not in lines]:
            await self.release(line, flush=False)

    async def close(self) -> None:
        """The service stops, the lease still held: every held line's marks written once
        more, then no more."""
        for line in list(self._writers):
            await self.release(line, flush=True)

    async def _write_on(self, line: str) -> None:
        while True:
            await asyncio.sleep(self.every)
            await self.write(line)

    def document(self, line: str, extra: Mapping[str, Any]) -> dict[str, Any]:
        """``line``'s marks, with ``extra`` (what was taken on the loop), in a thread: it
        reads the database."""
        drives = list(self.drives_of(line))
        doc = export(self.history, drives) if self.history is not None and drives else {}
        return {**doc, **extra}

    def _encoded(self, line: str, extra: Mapping[str, Any]) -> tuple[bytes, int]:
        """:meth:`document` encoded under the limit, in a thread: up to a megabyte of JSON,
        made again while entries are left out, must not hold the loop."""
        return encode(self.document(line, extra), self.limit)

    def _on_loop(self, line: str) -> dict[str, Any]:
        """What only the loop may read: the drives in maintenance and the describe book."""
        maintenance = self.runtime.snapshot.maintenance
        drives = self.drives_of(line)
        extra: dict[str, Any] = {
            "maintenance": {d: maintenance[d].reason for d in drives if d in maintenance}
        }
        if self.book is not None:
            extra["book"] = self.book.to_json()
        return extra

    async def write(self, line: str) -> bool:
        """``line``'s marks put when they changed; False when the put failed."""
        try:
            data, dropped = await asyncio.to_thread(self._encoded, line, self._on_loop(line))
        except (sqlite3.Error, ValueError, OSError) as exc:
            self._once(line, f"its marks cannot be made: {exc}")
            return False
        if dropped and line not in self._cut:
            self._cut.add(line)
            log.warning(
                "line %s: its marks exceed %d bytes: the %d oldest log entries are left out",
                line, self.limit, dropped, extra={"line": line},
            )  # fmt: skip
        if self._written.get(line) == data:
            return True
        if not await self.marks.put(line, MARK, data):
            self._once(line, "its marks could not be written to etcd (tried again later)")
            return False
        if line in self._failing:
            self._failing.discard(line)
            log.info("line %s: its marks are written to etcd again", line, extra={"line": line})
        self._written[line] = data
        return True

    def _once(self, line: str, what: str) -> None:
        if line not in self._failing:
            self._failing.add(line)
            log.warning("line %s: %s", line, what, extra={"line": line})
