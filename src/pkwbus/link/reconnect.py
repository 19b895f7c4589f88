"""A port's state and when to try it again: one object per line, testable without a port.

After a failure (a port that cannot be opened, or one that was lost) the next
attempt waits a capped exponential back-off. The back-off starts afresh only once
the port proved usable: a station answered on it (:meth:`Reconnect.usable`), or it
stayed open for :data:`SETTLED` seconds. A port that opens and is lost or refused
again at once (another master on the line, a gateway that accepts and closes) is
still in the same outage: it waits longer each time, and :attr:`Reconnect.repeated`
tells the listeners that the outage was told already. Every change of state goes to
the listeners, in the order they were added, as aioesphomeapi's ``ReconnectLogic``
does for its connections. The object keeps no clock: each call says what time it is.
"""

from __future__ import annotations

import enum
from collections.abc import Callable

from pkwbus.link.backoff import Backoff

__all__ = ["SETTLED", "LinkState", "Reconnect", "StateListener"]

SETTLED = 60.0  # seconds open without a failure: the port is usable, its back-off afresh


class LinkState(enum.Enum):
    CLOSED = "closed"
    OPEN = "open"
    FAILED = "failed"


StateListener = Callable[[LinkState, "str | None"], None]


class Reconnect:
    """State, back-off and listeners of one port."""

    def __init__(self, initial: float = 0.5, cap: float = 30.0, settled: float = SETTLED) -> None:
        self.state = LinkState.CLOSED
        self.last_error: str | None = None
        self.next_attempt = 0.0  # when the next attempt may start (loop time)
        # From a failure until the port proved usable again: one outage, told once.
        self.outage = False
        # The change the listeners hear now belongs to an outage they were told of: an
        # opening lost again at once after the one told, a failure as the one told before.
        self.repeated = False
        self.openings = 0  # the port's openings within the outage
        self._lost_open = False  # the latest failure was a loss of the open port
        self._settled = settled
        self._opened_at = 0.0
        self._backoff = Backoff(initial, cap)
        self._listeners: list[StateListener] = []

    def add_listener(self, listener: StateListener) -> Callable[[], None]:
        """Call ``listener(state, error)`` at every change; returns its removal."""
        self._listeners.append(listener)
        return lambda: self._listeners.remove(listener)

    def opened(self, now: float) -> None:
        """The port opened; its back-off stands until it proves usable."""
        self._opened_at = now
        if self.outage:
            self.openings += 1
        self.repeated = self.outage and self._lost_open and self.openings > 1
        self._set(LinkState.OPEN, None)

    def usable(self) -> int:
        """A station answered on the port: the outage is over, the back-off starts afresh.
        How many openings the outage took where some were not told (else 0)."""
        quiet = self.openings if self.outage and self._lost_open and self.openings > 1 else 0
        self.outage = False
        self.openings = 0
        self._backoff.reset()
        return quiet

    def failed(self, reason: str, now: float) -> None:
        """The port could not be opened or was lost: the next attempt waits a back-off,
        longer each time until the port proved usable (open for a while, say)."""
        if self.state is LinkState.OPEN and now - self._opened_at >= self._settled:
            self.usable()
        self.repeated = self.told(reason)
        self.outage = True
        self._lost_open = self.state is LinkState.OPEN
        self.next_attempt = now + self._backoff.next_delay()
        self.last_error = reason
        self._set(LinkState.FAILED, reason)

    def told(self, reason: str) -> bool:
        """Whether ``reason`` is the failure this outage was told of already (a line that is
        refused each time it opens: said once)."""
        return self.outage and reason == self.last_error

    def closed(self) -> None:
        """Closed on purpose (a stop, a reload): the next opening starts afresh."""
        self.usable()
        self._set(LinkState.CLOSED, None)

    def wait(self, now: float) -> float:
        """Seconds until the next attempt may start (0 when it may start now)."""
        return max(0.0, self.next_attempt - now)

    def _set(self, state: LinkState, error: str | None) -> None:
        if state is self.state:
            return
        self.state = state
        for listener in list(self._listeners):
            listener(state, error)
