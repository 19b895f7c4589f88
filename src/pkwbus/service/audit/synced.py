"""An SQLite database that loses nothing it has committed: the audit log's way, shared by
the service's other stores (the drives' log entries).

Write-ahead log, every commit synced (``synchronous=FULL``): a committed row survives a
killed process and a power cut. The write-ahead log is checkpointed every
:data:`WAL_PAGES` pages and cut back to :data:`WAL_BYTES` after a checkpoint, so that it
cannot take the room of the database on a small disk.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Final

__all__ = ["WAL_BYTES", "WAL_PAGES", "connect_synced"]

WAL_PAGES: Final = 64  # the write-ahead log is checkpointed once it holds this many pages
WAL_BYTES: Final = 262144  # and cut back to this size (64 pages of 4 KiB) after a checkpoint


def connect_synced(path: str | Path, schema: str) -> sqlite3.Connection:
    """The database at ``path`` (its folder made where missing), with ``schema``; autocommit
    (each store its own ``BEGIN``), usable from the service's worker threads.
    sqlite3.Error or OSError when it cannot be opened."""
    if str(path) != ":memory:":
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    db = sqlite3.connect(str(path), check_same_thread=False, isolation_level=None)
    try:
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("PRAGMA synchronous=FULL")
        db.execute(f"PRAGMA wal_autocheckpoint={WAL_PAGES}")
        db.execute(f"PRAGMA journal_size_limit={WAL_BYTES}")
        db.executescript(schema)
    except sqlite3.Error:
        db.close()
        raise
    return db
