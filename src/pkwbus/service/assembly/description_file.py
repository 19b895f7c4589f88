"""The drives' descriptions kept between runs: a small JSON file beside the audit database.

Keyed by what identifies a drive's model and software
(:mod:`pkwbus.master.planning.identity`), so that a restart does not describe
everything again and a drive replaced by another model is described afresh.
A file that cannot be read is logged once and started afresh: descriptions
are read from the drives again, nothing is lost. A file that cannot be
written is logged once; the service goes on with what it has in memory.

No disk on the event loop: :meth:`DescriptionFile.save` takes a copy of the
book there (its entries are immutable: a copy of two levels of dicts) and a
thread of its own makes the text and writes it, a new file synced and renamed
over the old one, so that a reader (or a power cut) finds the old file or the
new one, never half of one. One writer at a time; a save while it writes
waits for it, and of several the latest wins. The service's stop waits for
the writer (:meth:`DescriptionFile.settled`).
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import threading
import time
from pathlib import Path
from typing import Final

from pkwbus.master.planning.identity import DescriptionBook

__all__ = ["DescriptionFile", "description_path"]

log = logging.getLogger(__name__)

SETTLE_WITHIN: Final = 10.0  # seconds the service's stop waits for a write under way


def description_path(audit_db: Path) -> Path:
    """``var/audit.sqlite`` -> ``var/audit.sqlite.descriptions.json``."""
    return audit_db.with_name(audit_db.name + ".descriptions.json")


class DescriptionFile:
    """Loads the book once and stores it again whenever a drive described something new."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.book = self._load()
        self._failed = False
        self._lock = threading.Lock()  # the fields below, between the loop and the writer
        self._pending: DescriptionBook | None = None  # the copy the writer takes next
        self._writer: threading.Thread | None = None  # while it writes
        self._written = ""  # the text last written: drives of one kind tell the same
        self.saves = 0  # how many times the book was saved: changed (a line's marks ask)

    def _load(self) -> DescriptionBook:
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return DescriptionBook()
        except OSError as exc:
            log.warning("cannot read %s (%s): the drives are described afresh", self.path,
                        exc.strerror or exc)  # fmt: skip
            return DescriptionBook()
        try:
            return DescriptionBook.from_json(json.loads(text))
        except (ValueError, TypeError, RecursionError) as exc:  # JSONDecodeError is a ValueError
            log.warning("%s is not a file of drive descriptions (%s): the drives are"
                        " described afresh", self.path, exc)  # fmt: skip
            return DescriptionBook()

    def save(self) -> None:
        """Store the book as it is now, off the caller's thread (the writer's): a new file
        renamed over the old one, never half a file."""
        self.saves += 1
        copy = DescriptionBook()
        copy.entries = {identity: dict(found) for identity, found in self.book.entries.items()}
        with self._lock:
            self._pending = copy  # a copy the writer has not taken yet is replaced
            if self._writer is None:
                self._writer = threading.Thread(
                    target=self._write_all, name="pkwbus-descriptions", daemon=True
                )
                self._writer.start()

    def flush(self, timeout: float | None = None) -> bool:
        """Wait until what was saved is written (or ``timeout`` seconds); whether it is.
        Not on the event loop: :meth:`settled` there."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            with self._lock:
                writer = self._writer
            if writer is None:
                return True
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                return False
            writer.join(left)

    async def settled(self, timeout: float = SETTLE_WITHIN) -> None:
        """Wait, off the loop, until what was saved is written (the service's stop)."""
        if self._writer is None:
            return
        if not await asyncio.to_thread(self.flush, timeout):
            log.warning("the drives' descriptions are still being written to %s after %g s:"
                        " the service stops without them", self.path, timeout)  # fmt: skip

    def _write_all(self) -> None:
        """The writer: the latest copy saved, until none waits."""
        while True:
            with self._lock:
                book, self._pending = self._pending, None
                if book is None:
                    self._writer = None
                    return
            try:
                text = json.dumps(book.to_json(), indent=1)
                if text != self._written:
                    self._write(text)
            except Exception:  # a defect: logged, and the writer goes on with the next
                log.exception("the drives' descriptions could not be stored in %s", self.path)

    def _write(self, text: str) -> None:
        temporary = self.path.with_name(self.path.name + ".new")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with temporary.open("w", encoding="utf-8") as file:
                file.write(text)
                file.flush()
                os.fsync(file.fileno())
            os.replace(temporary, self.path)
        except OSError as exc:
            if not self._failed:
                log.warning("cannot store the drives' descriptions in %s (%s): they are"
                            " read from the drives again at the next start", self.path,
                            exc.strerror or exc)  # fmt: skip
            self._failed = True
            return
        if self._failed:
            log.info("the drives' descriptions are stored in %s again", self.path)
        self._failed = False
        self._written = text
