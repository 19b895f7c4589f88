"""A line's drive-memory marks carried across a move in hot standby (issue "hot standby",
item 5): the next master of a line neither tells the drives' old log entries again nor
loses a settings baseline nor forgets a drive in maintenance.

One JSON document per line, the mark ``memory`` (:class:`~pkwbus.service.standby.Marks`):
``events`` (the log entries kept of the line's drives, as the history database keeps
them: what was told), ``settings`` and ``swept`` (each drive's settings, baselines
included, and the identity and end of its last sweep), ``maintenance`` (the drives in
maintenance and why) and ``maintenance_by_api`` (those of them the API put in maintenance;
the others the configuration file did: a reason does not tell), ``book`` (the describe
book: drives' descriptions by model, shared by the instance's lines, so it is carried whole).

Merge rule, when this instance wins the line (before its watchers tell anything):

- a log entry is added when the local database does not hold it (by drive and key); one
  held locally stays as this instance saw it;
- a drive's settings are taken whole from etcd when etcd's last sweep (or baseline) of
  it is newer than the local one, or the local database has none: etcd wins for what
  this instance did not see itself, the newer view of a drive wins otherwise;
- a drive etcd says is in maintenance is put in maintenance here (since the move), as the
  API's when the API put it in maintenance there (a document without ``maintenance_by_api``,
  of an older instance: when its reason is not the configuration file's);
- a describe book entry is added when this instance has none for that model and
  parameter, or one with fewer elements read; its own stay.

Bound: a document stays under :data:`MAX_MARK_BYTES` (etcd takes 1.5 MiB a request); past
it the oldest log entries are left out (logged once a line): those could be told again.
Written while the line is held, every :data:`WRITE_EVERY` seconds when it changed, off
the loop (the database read in a thread) and never on the exchange path; a put that
fails is tried again at the next turn (not made again), logged once until one succeeds.

A turn costs what changed: the document is made again only when a count of what it is
made of moved - the history's changes of the line's drives' log entries, and of their
settings (:class:`~pkwbus.service.history.store.Changes`), the describe book's saves - or
the drives in maintenance differ; a turn with none reads and encodes nothing. Made again,
only the parts that changed are read and encoded again (:func:`pkwbus.service.history.marks.make`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import sqlite3
import time
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import Final, NamedTuple, Protocol

from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.master.snapshot import Maintained
from pkwbus.service.assembly.line_changes import CONFIGURED
from pkwbus.service.history.marks import Made, dumps, encode, export, make, merge
from pkwbus.service.history.store import EVENTS, SETTINGS, Changes
from pkwbus.service.runtime import LineTask, Runtime

__all__ = [
    "MARK", "MAX_MARK_BYTES", "WRITE_EVERY", "Kept", "LineMarks", "encode", "export", "merge",
]  # fmt: skip

log = logging.getLogger("pkwbus.service.standby")

MARK: Final = "memory"
MAX_MARK_BYTES: Final = 1_000_000
WRITE_EVERY: Final = 2.0


class Kept(NamedTuple):
    """A drive in maintenance, as a line's marks carry it: why, and whether the API (not the
    configuration file) put it there."""

    reason: str
    by_api: bool


# What a line's marks are made of, on the loop: its drives, the history's counts of their
# log entries' and settings' changes (None: not counted), the book's saves (None: not
# counted), the drives in maintenance.
Sources = tuple[tuple[str, ...], tuple[int | None, int | None], int | None, dict[str, Kept]]


class Saved(Protocol):
    """Where the describe book is kept on disk (:class:`.description_file.DescriptionFile`):
    ``saves`` counts its saves, one each time the book changed."""

    saves: int

    def save(self) -> None: ...


class MarkStore(Protocol):
    """What is asked of :class:`~pkwbus.service.standby.Marks`."""

    async def get(self, line: str, name: str) -> bytes | None: ...
    async def put(self, line: str, name: str, value: bytes) -> bool: ...


class LineMarks:
    """The marks of the lines this instance masters: loaded when it wins one, written
    while it holds it. ``history``: the history database (None: no drive memory kept,
    only maintenance is carried); ``drives_of``: the drives of a line; ``changes``: the
    history's count of its changes, ``saved``: the book's keeper, counting its saves
    (without either, that source is read and encoded every turn)."""

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
        changes: Changes | None = None,
    ) -> None:
        self.marks = marks
        self.runtime = runtime
        self.history = history
        self.drives_of = drives_of
        self.every = every
        self.limit = limit
        self.book = book
        self.saved = saved
        self.changes = changes
        self._made: dict[str, tuple[Sources, Made, bytes]] = {}  # of what, how, the bytes
        self._book: tuple[int, str] | None = None  # the book's JSON text at a count of saves
        self._writers: dict[str, asyncio.Task[None]] = {}
        self._written: dict[str, bytes] = {}
        self._failing: set[str] = set()
        self._cut: set[str] = set()

    async def load(self, line: str) -> dict[str, Kept]:
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
                if self.changes is not None:  # the marks of a line holding these drives too
                    drives = {r[1] for r in doc.get("events", [])}
                    drives |= {r[0] for r in [*doc.get("settings", []), *doc.get("swept", [])]}
                    self.changes.changed(EVENTS, drives)
                    self.changes.changed(SETTINGS, drives)
            self._merge_book(doc.get("book"))
            return _kept(doc.get("maintenance", {}), doc.get("maintenance_by_api"))
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

    def maintained(
        self, line: str, kept: Mapping[str, Kept], runner: LineTask | None = None
    ) -> None:
        """Put the drives of ``kept`` in maintenance on ``line``'s ``runner`` (None: the one
        running; a line started now is in the runtime's next load)."""
        runner = runner if runner is not None else self.runtime.runners.get(line)
        if runner is None:
            return
        for drive, (reason, by_api) in kept.items():
            if drive not in self.drives_of(line):
                continue
            if by_api:  # the API's on the other instance: the API's here
                self.runtime.hold_maintenance(drive, Maintained(reason, time.time()))
                self.runtime.show_maintenance(runner, drive)
            else:
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
        self._made.pop(line, None)
        for drive in self.drives_of(line):  # its master from now on keeps their maintenance
            self.runtime.end_maintenance(drive)

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

    def _sources(self, line: str) -> Sources:
        """What ``line``'s marks are made of, as counts of its changes (and the drives in
        maintenance, few: compared whole), on the loop."""
        drives = tuple(self.drives_of(line))
        counts: tuple[int | None, int | None] = (None, None)
        if self.changes is not None:
            counts = (self.changes.count(EVENTS, drives), self.changes.count(SETTINGS, drives))
        elif self.history is None or not drives:
            counts = (0, 0)  # nothing read
        saves = 0 if self.book is None else self.saved.saves if self.saved is not None else None
        maintenance = self.runtime.snapshot.maintenance
        api = self.runtime.api_maintenance
        kept = {d: Kept(m.reason, d in api) for d, m in maintenance.items() if d in drives}
        return drives, counts, saves, kept

    async def write(self, line: str) -> bool:
        """``line``'s marks put when they changed; False when the put failed. Made again
        only when what they are made of changed since they were last made."""
        sources = self._sources(line)  # before the read: a change meanwhile is made again
        _, counts, saves, _ = sources
        last = self._made.get(line)
        if last is not None and last[0] == sources and None not in (*counts, saves):
            data: bytes | None = last[2]  # nothing changed: nothing read, nothing encoded
        else:
            data = await self._make(line, sources, last[1] if last is not None else None)
        if data is None:
            return False
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

    async def _make(self, line: str, sources: Sources, last: Made | None) -> bytes | None:
        """``line``'s marks made again from ``last`` (what changed read and encoded, in a
        thread); None when they cannot be (logged once)."""
        drives, counts, saves, maintenance = sources
        book: str | DescriptionBook | None = None
        if self.book is not None:  # its JSON made again when it was saved since
            kept = self._book
            book = kept[1] if kept is not None and kept[0] == saves else _copy(self.book)
        try:
            made, data, dropped, text = await asyncio.to_thread(
                self._encoded, drives, counts, last, maintenance, book
            )
        except (sqlite3.Error, ValueError, OSError) as exc:
            self._once(line, f"its marks cannot be made: {exc}")
            return None
        if saves is not None and text is not None:
            self._book = (saves, text)
        if dropped and line not in self._cut:
            self._cut.add(line)
            log.warning(
                "line %s: its marks exceed %d bytes: the %d oldest log entries are left out",
                line, self.limit, dropped, extra={"line": line},
            )  # fmt: skip
        self._made[line] = (sources, made, data)
        return data

    def _encoded(
        self,
        drives: tuple[str, ...],
        counts: tuple[int | None, int | None],
        last: Made | None,
        maintenance: dict[str, Kept],
        book: str | DescriptionBook | None,
    ) -> tuple[Made, bytes, int, str | None]:
        """The marks made (:func:`pkwbus.service.history.marks.make`), in a thread: up to a
        megabyte of JSON must not hold the loop; and the book's JSON text."""
        text = book if book is None or isinstance(book, str) else dumps(book.to_json())
        by_api = sorted(d for d, kept in maintenance.items() if kept.by_api)
        extra = [
            ("maintenance", dumps({d: kept.reason for d, kept in maintenance.items()})),
            ("maintenance_by_api", dumps(by_api)),
        ]
        if text is not None:
            extra.append(("book", text))
        return (*make(self.history, drives, counts, last, extra, self.limit), text)

    def _once(self, line: str, what: str) -> None:
        if line not in self._failing:
            self._failing.add(line)
            log.warning("line %s: %s", line, what, extra={"line": line})


def _kept(found: object, by_api: object) -> dict[str, Kept]:
    """The drives in maintenance a line's marks carry (``found``: drive -> reason), and
    whether the API put each there (``by_api``: the list of those; None, of an older
    instance: when its reason is not the configuration file's)."""
    if not isinstance(found, dict):
        return {}
    api = {str(d) for d in by_api} if isinstance(by_api, list) else None
    return {
        str(d): Kept(str(r), str(d) in api if api is not None else str(r) != CONFIGURED)
        for d, r in found.items()
    }


def _copy(book: DescriptionBook) -> DescriptionBook:
    """``book`` as it is now, to be made JSON off the loop (its entries are immutable: a
    copy of two levels of dicts, as its keeper takes one)."""
    copy = DescriptionBook()
    copy.entries = {identity: dict(found) for identity, found in book.entries.items()}
    return copy
