"""The drives of a line waiting for their turn: two heaps, O(log n) in the number of drives.

A drive with a claim on the next exchange waits in the ready heap, by its
claim's key (priority, lagging, order, last served, slot); one without waits
in the timer heap, by the time it will have one (a poll due, a probe, a
job's deadline). Every entry carries the drive's version: a change of the
drive pushes a new entry, and the old one is skipped when it surfaces, so
nothing is ever searched or removed in the middle of a heap.
"""

from __future__ import annotations

import heapq
import itertools
from typing import Generic, Protocol, TypeVar

__all__ = ["Agenda", "Key"]

Key = tuple[int, int, float, int, int]  # priority, lagging, order, last served, slot
_EXPIRY = -1  # a timer entry that ends queued jobs at their deadline (not versioned)


class Waiting(Protocol):
    @property
    def version(self) -> int: ...


D = TypeVar("D", bound=Waiting)


class Agenda(Generic[D]):
    """Ready drives by key, the others by the time they will have a claim."""

    def __init__(self, drives: int) -> None:
        self._ready: list[tuple[Key, int, D]] = []
        self._timers: list[tuple[float, int, int, D]] = []
        self._seq = itertools.count()
        self._limit = 4 * drives + 64  # stale entries beyond this are swept out

    def grow(self, drives: int) -> None:
        """The line has ``drives`` drives now (one was added)."""
        self._limit = 4 * drives + 64

    def ready(self, d: D, key: Key) -> None:
        heapq.heappush(self._ready, (key, d.version, d))
        self._sweep()

    def later(self, d: D, at: float) -> None:
        heapq.heappush(self._timers, (at, next(self._seq), d.version, d))
        self._sweep()

    def expiry(self, d: D, deadline: float) -> None:
        """Look at ``d`` again at a queued job's deadline, whatever its version then."""
        heapq.heappush(self._timers, (deadline, next(self._seq), _EXPIRY, d))

    def due(self, now: float) -> list[D]:
        """The drives whose time has come (to be put where they belong now)."""
        timers, out = self._timers, []
        while timers and timers[0][0] <= now:
            _, _, version, d = heapq.heappop(timers)
            if version == _EXPIRY or version == d.version:
                out.append(d)
        return out

    def first(self) -> D | None:
        """The drive with the best claim, taken off the heap (None: none is ready)."""
        ready = self._ready
        while ready:
            _, version, d = heapq.heappop(ready)
            if version == d.version:
                return d
        return None

    def next_time(self) -> float | None:
        """When the earliest waiting drive has a claim (None: none waits)."""
        return self._timers[0][0] if self._timers else None

    def _sweep(self) -> None:
        if len(self._ready) + len(self._timers) <= self._limit:
            return
        self._ready = [e for e in self._ready if e[1] == e[2].version]
        heapq.heapify(self._ready)
        self._timers = [e for e in self._timers if e[2] in (_EXPIRY, e[3].version)]
        heapq.heapify(self._timers)
