"""Which lines an instance campaigns for, and which one it gives away: the fair share.

An instance campaigns for a free line while it masters fewer than
``ceil(lines / live instances)`` (:func:`share`); alone, it takes them all. Three rules
keep every line mastered when the count of live instances is not the whole truth (an
instance killed is still registered until its own lease expires; an instance's
configuration may lack a line):

- **orphans**: a line free for ``orphan_grace`` is campaigned for whatever the share,
  so a line is never left without a master because its fair taker is gone; the
  instances under their share had the time to take it first;
- **rebalance on join**: an instance over its share gives one line away (the last of
  its lines in order, never one it took as an orphan) only for ``window`` seconds after
  another instance registered anew, only while some other live instance masters fewer
  than the share, and one at a time: the next after the last was taken;
- **no ping-pong**: a line given away is not taken back by the giver for
  ``retake_after`` seconds (then it is an orphan like any other).

Pure: the state is given, nothing is asked of etcd or the clock.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field

__all__ = ["Policy", "Situation", "order", "share"]


def share(lines: int, live: int) -> int:
    """The most lines one of ``live`` instances campaigns for: ceil(lines / live)."""
    return math.ceil(lines / max(1, live))


def order(lines: Sequence[str], me: str) -> list[str]:
    """``lines`` in the order ``me`` campaigns: rotated by a hash of its name, so that
    instances starting together go for different lines first."""
    if not lines:
        return []
    start = zlib.crc32(me.encode()) % len(lines)
    return [*lines[start:], *lines[:start]]


@dataclass(frozen=True)
class Situation:
    """What an instance knows now."""

    me: str
    lines: Sequence[str]  # this instance's lines, in the configuration's order
    holders: Mapping[str, str]  # line -> name of the instance mastering it (absent: free)
    live: Collection[str]  # instances registered now (me counted whether there or not)
    now: float
    free_since: Mapping[str, float] = field(default_factory=dict)  # line -> seen free at
    given: Mapping[str, float] = field(default_factory=dict)  # line -> given away by me at
    orphans: Collection[str] = ()  # lines I took as orphans
    joined: float | None = None  # when another instance last registered anew

    @property
    def instances(self) -> int:
        return len(set(self.live) | {self.me})

    @property
    def mine(self) -> list[str]:
        return [line for line in self.lines if self.holders.get(line) == self.me]

    def masters(self, name: str) -> int:
        return sum(1 for line in self.lines if self.holders.get(line) == name)


@dataclass(frozen=True)
class Policy:
    orphan_grace: float  # a free line is anyone's after this
    retake_after: float  # a line given away is not taken back before this
    window: float  # lines are given away this long after an instance joined

    def campaign(self, s: Situation) -> list[str]:
        """The free lines to campaign for now, in order: first those within the share,
        then the orphans."""
        quota = share(len(s.lines), s.instances) - len(s.mine)
        free = [
            line
            for line in order(s.lines, s.me)
            if line not in s.holders
            and not (line in s.given and s.now - s.given[line] < self.retake_after)
        ]
        fair = free[: max(0, quota)]
        orphans = [
            line
            for line in free
            if line not in fair and s.now - s.free_since.get(line, s.now) >= self.orphan_grace
        ]
        return fair + orphans

    def give_away(self, s: Situation) -> str | None:
        """The line to give away now, if any (see the module's rules)."""
        if s.joined is None or s.now - s.joined > self.window:
            return None
        if any(
            line not in s.holders and s.now - at < self.retake_after for line, at in s.given.items()
        ):
            return None  # the last one given is not taken yet
        fair = share(len(s.lines), s.instances)
        if len(s.mine) <= fair:
            return None
        if not any(s.masters(other) < fair for other in set(s.live) - {s.me}):
            return None
        candidates = [line for line in s.mine if line not in s.orphans]
        return candidates[-1] if candidates else None
