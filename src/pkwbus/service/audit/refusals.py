"""The tallies of requests refused for want of a valid token: one row per address and minute.

A flood of such requests can neither grow the audit database nor cost a write
each: they are counted here, in memory, and :class:`~pkwbus.service.audit.log.AuditLog`
writes each address's tally once its minute has ended (and at shutdown, and
before an authorised read of the log). Past :data:`MAX_SOURCES_PER_MINUTE`
addresses in a minute the rest share the tally of :data:`OTHER_SOURCES`.

Tallies that cannot be written stay here, at most :data:`MAX_PENDING_MINUTES`
minutes of them; older ones are given up (:meth:`RefusalTallies.give_up`), so
a log that cannot record for hours does not take the memory.

This module only counts; the store is the caller's. Not thread-safe: the caller
holds its lock. Raises nothing.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Final

__all__ = [
    "MAX_PENDING_MINUTES",
    "MAX_SOURCES_PER_MINUTE",
    "OTHER_SOURCES",
    "RefusalTallies",
    "Tally",
    "minute_of",
]

MAX_SOURCES_PER_MINUTE: Final = 32  # refusal rows per minute; more addresses share one row
OTHER_SOURCES: Final = "other addresses"
MAX_PENDING_MINUTES: Final = 60  # minutes of tallies kept while the log cannot record


def minute_of(now: float) -> int:
    return int(now // 60)


@dataclass
class Tally:
    """One address's refusals in one minute: when the first came, how many of each kind,
    its row once written (None before) and the count that row holds."""

    minute: int
    client: str
    time: float
    kinds: Counter[str] = field(default_factory=Counter)
    row: int | None = None
    saved: int = 0

    @property
    def count(self) -> int:
        return sum(self.kinds.values())

    @property
    def dirty(self) -> bool:
        """Whether it counts more than its row says."""
        return self.count > self.saved

    @property
    def detail(self) -> str:
        return "refused without a valid token: " + ", ".join(
            f"{k} {n}" for k, n in sorted(self.kinds.items())
        )


class RefusalTallies:
    """The refusals of each minute by address, until they are written."""

    def __init__(self, max_minutes: int = MAX_PENDING_MINUTES) -> None:
        self.max_minutes = max_minutes
        self._minutes: dict[int, dict[str, Tally]] = {}

    def count(self, now: float, client: str, kind: str) -> None:
        """One more refusal of ``kind`` from ``client`` at ``now``."""
        minute = minute_of(now)
        tallies = self._minutes.setdefault(minute, {})
        if client not in tallies and len(tallies) >= MAX_SOURCES_PER_MINUTE:
            client = OTHER_SOURCES
        tally = tallies.get(client)
        if tally is None:
            tally = tallies[client] = Tally(minute, client, now)
        tally.kinds[kind] += 1

    def due(self, now: float | None = None) -> list[Tally]:
        """The tallies not written as they stand, of minutes ended before ``now``'s
        (None: of every minute, this one too), oldest first."""
        last = None if now is None else minute_of(now)
        return [
            tally
            for minute in sorted(self._minutes)
            if last is None or minute < last
            for tally in self._minutes[minute].values()
            if tally.dirty
        ]

    def written(self, tallies: list[Tally], rows: list[int], now: float) -> None:
        """``tallies`` stand in ``rows`` now; the minutes ended before ``now``'s whose
        tallies are all written are forgotten."""
        for tally, row in zip(tallies, rows, strict=True):
            tally.row, tally.saved = row, tally.count
        current = minute_of(now)
        for minute in [m for m, t in self._minutes.items() if m < current]:
            if not any(tally.dirty for tally in self._minutes[minute].values()):
                del self._minutes[minute]

    def give_up(self) -> list[Tally]:
        """The tallies of the oldest minutes beyond :attr:`max_minutes`, forgotten."""
        dropped: list[Tally] = []
        while len(self._minutes) > self.max_minutes:
            oldest = min(self._minutes)
            dropped.extend(t for t in self._minutes.pop(oldest).values() if t.dirty)
        return dropped

    def pending(self) -> int:
        """Refusals counted and not yet written."""
        return sum(
            t.count - t.saved for tallies in self._minutes.values() for t in tallies.values()
        )
