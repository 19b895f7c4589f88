"""The audit log's token fingerprints: an HMAC-SHA256 keyed with this installation's secret.

The secret is kept beside the database (``<audit_db>.key``, mode 0600, made
and synced on the first start): the same token has the same id across
restarts, and nobody without the key can test a guess of the token against it.

Raises :class:`OSError` from :func:`load_key` when the key file cannot be made
or read, is not a regular file, or is damaged (the message says what to do).
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import os
import secrets
from pathlib import Path
from typing import Final

__all__ = ["KEY_BYTES", "TOKEN_ID_HEX", "fingerprint", "key_path", "load_key", "new_key"]

KEY_BYTES: Final = 32
TOKEN_ID_HEX: Final = 16  # 64 bits of the HMAC: distinct for any number of tokens in use


def key_path(db: Path) -> Path:
    """Where the token-fingerprint secret of the database ``db`` lives."""
    return db.with_name(db.name + ".key")


def new_key() -> bytes:
    """A secret that lives as long as the process (an in-memory audit log's)."""
    return secrets.token_bytes(KEY_BYTES)


def fingerprint(key: bytes, token: str) -> str:
    """The token's id: HMAC-SHA256 keyed with ``key``, cut to :data:`TOKEN_ID_HEX` digits."""
    digest = hmac.new(key, token.encode(), hashlib.sha256).hexdigest()
    return "hmac:" + digest[:TOKEN_ID_HEX]


def load_key(db: Path) -> bytes:
    """The installation's secret, made on first use (mode 0600, synced)."""
    path = key_path(db)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    try:
        fd = os.open(path, flags, 0o600)
    except FileExistsError:
        return _read_key(path)
    key = secrets.token_bytes(KEY_BYTES)
    try:
        os.write(fd, key.hex().encode() + b"\n")
        os.fsync(fd)
    except OSError:
        os.close(fd)
        path.unlink(missing_ok=True)  # no half-written key for the next start to trip on
        raise
    os.close(fd)
    with contextlib.suppress(OSError):  # the new name survives a power cut too
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    return key


def _read_key(path: Path) -> bytes:
    if not path.is_file():
        raise OSError(f"{path} is not a regular file")
    text = path.read_text(errors="replace").strip()
    try:
        key = bytes.fromhex(text)
    except ValueError:
        key = b""
    if len(key) != KEY_BYTES:
        raise OSError(
            f"the key file {path} is damaged (not {KEY_BYTES * 2} hex digits): restore it,"
            " or delete it to start new token ids"
        )
    return key
