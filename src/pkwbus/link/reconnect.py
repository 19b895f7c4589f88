"""A port's state and when to try it again: one object per line, testable without a port.

After a failure (a port that cannot be opened, or one that was lost) the next
attempt waits a capped exponential back-off, reset once the port opens. Every
change of state goes to the listeners, in the order they were added, as
aioesphomeapi's ``ReconnectLogic`` does for its connections. The object keeps
no clock: each call says what time it is.
"""

from __future__ import annotations

import enum
from collections.abc import Callable

from pkwbus.link.backoff import Backoff

__all__ = ["LinkState", "Reconnect", "StateListener"]


class LinkState(enum.Enum):
    CLOSED = "closed"
    OPEN = "open"
    FAILED = "failed"


StateListener = Callable[[LinkState, "str | None"], None]


class Reconnect:
    """State, back-off and listeners of one port."""

    def __init__(self, initial: float = 0.5, cap: float = 30.0) -> None:
        self.state = LinkState.CLOSED
        self.last_error: str | None = None
        self.next_attempt = 0.0  # when the next attempt may start (loop time)
        self._backoff = Backoff(initial, cap)
        self._listeners: list[StateListener] = []

    def add_listener(self, listener: StateListener) -> Callable[[], None]:
        """Call ``listener(state, error)`` at every change; returns its removal."""
        self._listeners.append(listener)
        return lambda: self._listeners.remove(listener)

    def opened(self) -> None:
        self._backoff.reset()
        self._set(LinkState.OPEN, None)

    def failed(self, reason: str, now: float) -> None:
        """The port could not be opened or was lost: the next attempt waits a back-off."""
        self.next_attempt = now + self._backoff.next_delay()
        self.last_error = reason
        self._set(LinkState.FAILED, reason)

    def closed(self) -> None:
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
