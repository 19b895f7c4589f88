"""What keeps a port silent once its line may be another instance's (hot standby).

A :class:`Fence` gives the moment on ``time.monotonic()`` up to which its line's
port may transmit. :class:`~pkwbus.link.port.Link` asks it before it opens the
port and before every write, so that a process resumed after SIGSTOP, or one
whose lease renewals stopped, never sends a byte on a stale lease: the write is
refused and the port given up, the reason told. A single instance's lines have
:data:`ALWAYS_OPEN`, which never closes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Protocol

__all__ = ["ALWAYS_OPEN", "Fence", "LineFence", "fence_closed", "fenced_reason"]


class Fence(Protocol):
    def open_until(self) -> float:
        """The ``time.monotonic()`` moment from which the port may no longer transmit."""
        ...


class _AlwaysOpen:
    def open_until(self) -> float:
        return math.inf

    def __repr__(self) -> str:
        return "ALWAYS_OPEN"


ALWAYS_OPEN: Fence = _AlwaysOpen()


@dataclass(frozen=True)
class LineFence:
    """A line's fence named by its line, so that a refusal says which lease expired."""

    line: str
    fence: Fence

    def open_until(self) -> float:
        return self.fence.open_until()


def fence_closed(fence: Fence) -> bool:
    """Whether ``fence`` forbids transmitting now."""
    return time.monotonic() >= fence.open_until()


def fenced_reason(fence: Fence) -> str:
    """Why a closed ``fence`` keeps the port shut, for people."""
    if isinstance(fence, LineFence):
        return f"lease of line {fence.line} expired (hot standby): the port is given up"
    return "lease of its line expired (hot standby): the port is given up"
