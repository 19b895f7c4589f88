"""How long a master may transmit on its lease: the fence's arithmetic, on its own clock.

etcd's leader expires a lease ``TTL`` seconds after it last received a renewal, on the
leader's clock. A renewal received was sent earlier, so ``sent + TTL`` on the master's
clock (``link.fence.FENCE_CLOCK``) is no later than that expiry, if both clocks ran at
the same rate. The master stops transmitting a safety margin before that moment::

    open_until = sent + min(TTL, lease) - margin(lease)

``sent`` being when the last *successful* renewal was sent (not answered): whatever
the time its answer took to arrive, or whether the process was stopped (SIGSTOP) or not
scheduled in between, the fence only gets earlier.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

__all__ = [
    "MIN_MARGIN",
    "LeaseClock",
    "LineLeaseFence",
    "margin",
    "renew_every",
    "request_timeout",
    "retry_every",
]

MIN_MARGIN: Final = 1.0


def margin(lease: float) -> float:
    """The safety margin: max(1 s, lease / 4).

    It covers two things. (1) Clock-rate drift: the master's clock may run
    slower than the etcd leader's; quartz and NTP slewing keep that far below 0.1 %
    (500 ppm at most when slewed), which is < 30 ms of a 60 s lease; the margin leaves
    25 % of the lease, so it covers rates up to 25 % apart. (2) The time to stop a
    write: the port checks the fence before each write, but a telegram handed to the
    driver just before goes on for its transmit time (a 255-byte PROFIBUS frame at
    9600 baud takes 0.3 s), and the check and the write run on a busy event loop. At
    least 1 s for short leases, where a quarter would leave too little for that.
    """
    return max(MIN_MARGIN, lease / 4)


def renew_every(lease: float) -> float:
    """The renewal period: lease / 3, so two renewals in a row may fail before the
    fence closes (it closes at lease - margin, at least lease / 2 after a renewal)."""
    return lease / 3


def request_timeout(lease: float) -> float:
    """One try of one request, well under the lease: lease / 8, from 0.5 s to 2 s. A
    renewal may then try a few endpoints before the fence closes."""
    return min(2.0, max(0.5, lease / 8))


def retry_every(lease: float) -> float:
    """How soon a failed renewal is tried again: lease / 12, at most 0.5 s."""
    return min(0.5, lease / 12)


@dataclass
class LeaseClock:
    """One lease's fence: until when its keys' lines may be transmitted on."""

    lease: float
    clock: Callable[[], float]
    _open_until: float = field(default=0.0, init=False)

    @property
    def margin(self) -> float:
        return margin(self.lease)

    def renewed(self, sent: float, ttl: float) -> None:
        """A grant or renewal sent at ``sent`` was answered with ``ttl`` seconds left
        (etcd's whole seconds; 0 or less: the lease is gone, the fence closes)."""
        if ttl <= 0:
            self._open_until = 0.0
            return
        until = sent + min(float(ttl), self.lease) - self.margin
        # a late answer to an older renewal never moves the fence back
        self._open_until = max(self._open_until, until)

    def close(self) -> None:
        self._open_until = 0.0

    def open_until(self) -> float:
        return self._open_until

    def is_open(self) -> bool:
        return self.clock() < self._open_until

    def left(self) -> float:
        """Seconds until the fence closes (0 when closed)."""
        return max(0.0, self._open_until - self.clock())


class LineLeaseFence:
    """A line's fence (``link.fence.Fence``): open while this instance holds the line
    on a lease whose fence is open; ``open_until()`` is 0.0 while the line is not held."""

    def __init__(self, line: str, held: Callable[[str], LeaseClock | None]) -> None:
        self.line = line
        self._held = held

    def open_until(self) -> float:
        lease = self._held(self.line)
        return 0.0 if lease is None else lease.open_until()

    def __repr__(self) -> str:
        until = self.open_until()
        return f"LineLeaseFence({self.line!r}, open_until={until if math.isfinite(until) else 0})"
