"""One master per line: which device a port string names, and who holds a port.

FC and USS have no bus arbitration: two masters on one RS-485 line collide,
and either may take the other's answer for its own. pkwbus opens a serial
device exclusively (an advisory ``flock``, as pyserial's ``exclusive=True``
does), so that a second pkwbus process is refused; and a configuration may
not name one device twice, through a symlink (``/dev/serial/by-id/...``) or
not. A ``socket://`` or ``rfc2217://`` port is one TCP endpoint: its gateway
decides whether a second connection is let in.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from pkwbus.link.settings import PortError

__all__ = ["PortBusy", "holders", "same_line"]

_TCP_SCHEMES = ("socket", "rfc2217")
_PROC = Path("/proc")


class PortBusy(PortError):
    """The port is held by another process (another master of the line)."""


def same_line(url: str) -> str:
    """A key that two port strings share when they name one line: a device's major and
    minor number (or its resolved path where it does not exist here), a TCP endpoint's
    host and port; a ``loop://`` or other URL is its own."""
    scheme, sep, rest = url.partition("://")
    if sep:
        if scheme.casefold() in _TCP_SCHEMES:
            address = rest.split("?", 1)[0].split("/", 1)[0]
            return f"tcp:{address.casefold()}"
        return f"url:{url}"
    path = os.path.realpath(os.path.expanduser(url))
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return f"path:{path}"
    if stat.S_ISCHR(st.st_mode):
        return f"device:{os.major(st.st_rdev)}:{os.minor(st.st_rdev)}"
    return f"path:{path}"


def holders(url: str) -> list[str]:
    """The other processes that hold the device's lock, as ``pid N: command``, where the
    system tells (Linux ``/proc/locks``); empty otherwise."""
    try:
        st = os.stat(url)
        locks = (_PROC / "locks").read_text(encoding="ascii", errors="replace")
    except (OSError, ValueError):
        return []
    # "1: FLOCK  ADVISORY  WRITE 1234 00:05:87 0 EOF": the file as major:minor (hex) of
    # its file system and its inode number (proc(5), /proc/locks).
    mine = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    found: list[str] = []
    for line in locks.splitlines():
        fields = line.split()
        if "->" in fields:  # a process waiting for the lock, not one holding it
            continue
        if len(fields) >= 6 and fields[5] == mine and fields[4].isdigit():
            pid = int(fields[4])
            if pid != os.getpid():
                found.append(f"pid {pid}: {_command(_PROC / str(pid))}")
    return sorted(set(found))


def _command(proc: Path) -> str:
    try:
        words = (proc / "cmdline").read_bytes().split(b"\0")
    except OSError:
        return "?"
    text = " ".join(w.decode("utf-8", "replace") for w in words if w)
    return text[:80] + ("..." if len(text) > 80 else "") if text else "?"
