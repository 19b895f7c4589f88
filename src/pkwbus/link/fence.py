"""What keeps a port silent once its line may be another instance's (hot standby).

A :class:`Fence` gives the moment on :data:`FENCE_CLOCK` up to which its line's
port may transmit. :class:`~pkwbus.link.port.Link` asks it before it opens the
port and before every write, so that a process resumed after SIGSTOP, or one
whose lease renewals stopped, never sends a byte on a stale lease: the write is
refused and the port given up, the reason told. A single instance's lines have
:data:`ALWAYS_OPEN`, which never closes.

:data:`FENCE_CLOCK` is the one clock of every lease deadline (the lease keeper's, the
fence's, the standby engine's and the port's check), picked here by :func:`pick_clock`:
``CLOCK_BOOTTIME`` where the system has it (Linux), which counts a system suspend as
time passed, where ``time.monotonic()`` stops; elsewhere ``time.monotonic()``.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Protocol

__all__ = [
    "ALWAYS_OPEN",
    "FENCE_CLOCK",
    "Fence",
    "LineFence",
    "fence_closed",
    "fenced_reason",
    "pick_clock",
]


def pick_clock() -> Callable[[], float]:
    """The clock of the leases' deadlines: ``CLOCK_BOOTTIME`` where there is one (a
    master whose host was suspended finds its lease past when it resumes), else
    ``time.monotonic``."""
    boottime: int | None = getattr(time, "CLOCK_BOOTTIME", None)
    if boottime is None:
        return time.monotonic
    return functools.partial(time.clock_gettime, boottime)


FENCE_CLOCK: Final[Callable[[], float]] = pick_clock()


class Fence(Protocol):
    def open_until(self) -> float:
        """The :data:`FENCE_CLOCK` moment from which the port may no longer transmit."""
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


def fence_closed(fence: Fence, clock: Callable[[], float] = FENCE_CLOCK) -> bool:
    """Whether ``fence`` forbids transmitting now (``clock``: the fences' own)."""
    return clock() >= fence.open_until()


def fenced_reason(fence: Fence) -> str:
    """Why a closed ``fence`` keeps the port shut, for people: the line is no longer this
    instance's to master (its lease expired, or it was handed over to another instance)."""
    line = f"line {fence.line}" if isinstance(fence, LineFence) else "its line"
    return (
        f"{line} is no longer mastered here (hot standby: its lease ended or the line was"
        " handed over): the port is given up"
    )
