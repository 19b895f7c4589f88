"""Whether a path can be the audit database on this machine: :func:`path_problem`.

Raises nothing: a problem is returned as one line.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from pkwbus.service.audit.key import key_path

__all__ = ["path_problem"]


def path_problem(db: Path, what: str = "the audit database") -> str | None:
    """Why ``db`` cannot be ``what`` (the audit database, with its key file; or another
    SQLite database of the service) on this machine, or None.

    A file there must be a regular, writable file; otherwise the nearest existing
    directory above it must be writable (the service makes the missing ones).
    """
    if str(db) == ":memory:":
        return None
    files = [(db, what)]
    if what == "the audit database":
        files.append((key_path(db), "its key file"))
    for path, what in files:
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
