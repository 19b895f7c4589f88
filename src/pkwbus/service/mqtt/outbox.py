"""The outbox: the QoS 1 messages (drive events) kept on disk until the broker
acknowledged them, in SQLite beside the audit database.

Every call runs on the outbox's own thread (:meth:`Outbox.call`), never on the event
loop. A message is stored before it is sent and deleted only once the broker
acknowledged it (PUBACK), so a broker away or a service killed loses none; they go out
again in the order they were stored. ``max_bytes`` and ``max_age`` cap what is kept:
the oldest go first, each counted as dropped. Values are never stored.
"""

from __future__ import annotations

import asyncio
import sqlite3
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from pkwbus.errors import PkwbusError

__all__ = ["Outbox", "OutboxError", "Stored", "outbox_path"]

T = TypeVar("T")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS outbox (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    topic TEXT NOT NULL,
    payload BLOB NOT NULL,
    stored REAL NOT NULL
);
CREATE INDEX IF NOT EXISTS outbox_stored ON outbox (stored)
"""


class OutboxError(PkwbusError):
    """The outbox's database cannot be opened or written."""


def outbox_path(audit_db: Path) -> Path:
    """Where the outbox is kept: beside the audit database."""
    return audit_db.with_name("mqtt-outbox.sqlite")


@dataclass(frozen=True, slots=True)
class Stored:
    """A message as the outbox keeps it: its number (the order), topic, payload and when
    it was stored (wall clock)."""

    id: int
    topic: str
    payload: bytes
    stored: float


class Outbox:
    """The outbox at ``path`` (see the module); ``clock`` for tests."""

    def __init__(
        self,
        path: Path,
        max_bytes: int,
        max_age: float,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.path = path
        self.max_bytes = max_bytes
        self.max_age = max_age
        self.clock = clock
        self._thread = ThreadPoolExecutor(1, thread_name_prefix="mqtt-outbox")
        self._db: sqlite3.Connection | None = None
        self.messages = 0  # what it keeps now (the thread's; read anywhere)
        self.bytes = 0

    async def call(self, work: Callable[[], T]) -> T:
        """``work`` on the outbox's thread."""
        return await asyncio.get_running_loop().run_in_executor(self._thread, work)

    def _open(self) -> sqlite3.Connection:
        if self._db is None:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                # Used by the one thread of call() alone (a test may call it directly).
                db = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
                db.execute("PRAGMA journal_mode=WAL")
                db.execute("PRAGMA synchronous=FULL")  # stored means kept, even at a crash
                db.executescript(_SCHEMA)
                self.messages, self.bytes = db.execute(
                    "SELECT COUNT(*), COALESCE(SUM(LENGTH(payload)), 0) FROM outbox"
                ).fetchone()
            except (sqlite3.Error, OSError) as exc:
                raise OutboxError(f"the MQTT outbox {self.path} cannot be opened: {exc}") from None
            self._db = db
        return self._db

    # Each below runs on the thread (through call).

    def add(self, messages: Sequence[tuple[str, bytes]]) -> int:
        """Store ``messages`` (topic, payload) in their order; how many old ones were
        dropped to stay within max_bytes and max_age."""
        db, now = self._open(), self.clock()
        try:
            with db:
                db.executemany(
                    "INSERT INTO outbox (topic, payload, stored) VALUES (?, ?, ?)",
                    [(topic, payload, now) for topic, payload in messages],
                )
        except sqlite3.Error as exc:
            raise OutboxError(f"the MQTT outbox cannot store: {exc}") from None
        self.messages += len(messages)
        self.bytes += sum(len(p) for _, p in messages)
        return self._trim(db, now)

    def oldest(self, limit: int) -> tuple[list[Stored], int]:
        """The ``limit`` oldest messages kept, and how many were dropped for their age."""
        db = self._open()
        dropped = self._trim(db, self.clock())
        rows = db.execute(
            "SELECT id, topic, payload, stored FROM outbox ORDER BY id LIMIT ?", (limit,)
        ).fetchall()
        return [Stored(i, t, bytes(p), s) for i, t, p, s in rows], dropped

    def delete(self, ids: Sequence[int]) -> None:
        """The messages the broker acknowledged, gone."""
        if not ids:
            return
        db = self._open()
        with db:
            marks = ",".join("?" * len(ids))
            size = db.execute(
                f"SELECT COUNT(*), COALESCE(SUM(LENGTH(payload)), 0) FROM outbox"
                f" WHERE id IN ({marks})", tuple(ids),
            ).fetchone()  # fmt: skip
            db.execute(f"DELETE FROM outbox WHERE id IN ({marks})", tuple(ids))
        self.messages -= size[0]
        self.bytes -= size[1]

    def size(self) -> tuple[int, int]:
        """(messages, bytes) kept."""
        self._open()
        return self.messages, self.bytes

    def _trim(self, db: sqlite3.Connection, now: float) -> int:
        """Drop what is older than max_age, then the oldest while over max_bytes."""
        dropped = 0
        with db:
            cur = db.execute(
                "SELECT COUNT(*), COALESCE(SUM(LENGTH(payload)), 0) FROM outbox WHERE stored < ?",
                (now - self.max_age,),
            )
            count, size = cur.fetchone()
            if count:
                db.execute("DELETE FROM outbox WHERE stored < ?", (now - self.max_age,))
                dropped += count
                self.messages -= count
                self.bytes -= size
            while self.bytes > self.max_bytes and self.messages:
                over = self.bytes - self.max_bytes
                rows = db.execute(
                    "SELECT id, LENGTH(payload) FROM outbox ORDER BY id LIMIT 256"
                ).fetchall()
                gone: list[int] = []
                for row_id, length in rows:
                    if over <= 0:
                        break
                    gone.append(row_id)
                    over -= length
                    self.bytes -= length
                    self.messages -= 1
                db.execute("DELETE FROM outbox WHERE id <= ?", (gone[-1],))
                dropped += len(gone)
        return dropped

    def close(self) -> None:
        """Close the database (on the thread) and end the thread."""

        def _close() -> None:
            if self._db is not None:
                self._db.close()
                self._db = None

        self._thread.submit(_close).result()
        self._thread.shutdown(wait=True)
