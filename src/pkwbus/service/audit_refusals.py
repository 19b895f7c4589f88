"""The tallies of requests refused for want of a valid token: one row per address and minute.

A flood of such requests cannot grow the audit database: each address gets
one row a minute whose ``count`` rises with every further attempt, and past
:data:`MAX_SOURCES_PER_MINUTE` addresses in a minute the rest share the row of
:data:`OTHER_SOURCES`. This module only keeps the tallies (which row counts an
address this minute, by kind); :class:`~pkwbus.service.audit.AuditLog` stores
them. Raises nothing.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Final

__all__ = ["MAX_SOURCES_PER_MINUTE", "OTHER_SOURCES", "Refusal", "RefusalTallies"]

MAX_SOURCES_PER_MINUTE: Final = 32  # refusal rows per minute; more addresses share one row
OTHER_SOURCES: Final = "other addresses"


@dataclass(frozen=True)
class Refusal:
    """One more refusal: the row's address, its counts by kind with this one, and the
    row counting it this minute (None: a new row is due)."""

    client: str
    kinds: Counter[str]
    row: int | None

    @property
    def detail(self) -> str:
        return "refused without a valid token: " + ", ".join(
            f"{k} {n}" for k, n in sorted(self.kinds.items())
        )


@dataclass
class _Tally:
    """This minute's refusals from one address: the row that counts them, by kind."""

    row: int
    kinds: Counter[str] = field(default_factory=Counter)


class RefusalTallies:
    """This minute's refusals by address. Not thread-safe: the caller holds its lock."""

    def __init__(self) -> None:
        self._minute: int | None = None
        self._tallies: dict[str, _Tally] = {}

    def next(self, now: float, client: str, kind: str) -> Refusal:
        """What one more refusal of ``kind`` from ``client`` at ``now`` comes to; the
        tallies change only with :meth:`stored`, once its row is."""
        minute = int(now // 60)
        if minute != self._minute:
            self._minute, self._tallies = minute, {}
        if client not in self._tallies and len(self._tallies) >= MAX_SOURCES_PER_MINUTE:
            client = OTHER_SOURCES
        tally = self._tallies.get(client)
        kinds = Counter({kind: 1}) + (tally.kinds if tally else Counter())
        return Refusal(client, kinds, tally.row if tally else None)

    def stored(self, refusal: Refusal, row: int) -> None:
        """``refusal`` is in ``row``: further ones this minute count there."""
        tally = self._tallies.get(refusal.client)
        if tally is None:
            self._tallies[refusal.client] = _Tally(row, refusal.kinds)
        else:
            tally.kinds = refusal.kinds
