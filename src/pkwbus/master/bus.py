"""What a line's runner drives: the port of its bus and the wire that speaks it.

:class:`Port` is the I/O of one line (one request at a time); :class:`Wire` is
a kind of line, a few pure calls about what goes out and what came back
(:mod:`pkwbus.master.wires`). The runner (:mod:`pkwbus.master.runner`) is the
only one that calls them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from pkwbus.link import Link, PortError
from pkwbus.master.events import Event
from pkwbus.master.planning.planner import Planner

__all__ = ["Done", "LineRefused", "Port", "Wire"]

Done = Callable[[Any], None]


class LineRefused(PortError):
    """The line cannot be used though its port is open (another master runs it): the port
    is given up, and opened again at back-off."""


class Port(Protocol):
    """The I/O of one line: its link, and one request at a time."""

    @property
    def link(self) -> Link: ...

    @property
    def sent_at(self) -> float:
        """Loop time the latest request was written."""
        ...

    async def started(self) -> None:
        """The port just opened: what the bus asks before the first request (a DP master
        listens for other masters); :class:`LineRefused` when the line is not to be used."""
        ...

    def start(self, request: Any, done: Done) -> None:
        """Send ``request``; ``done`` gets its answer, or the exception that ended it."""
        ...

    async def close(self) -> None:
        """The line stops: what the bus asks first (a DP master clears its slaves), then
        the port closes."""
        ...


class Wire(Protocol):
    """A kind of line: pure calls about what goes out and what came back; no runner."""

    @property
    def port(self) -> Port: ...

    def poll_deadline(self, retries: int) -> float:
        """How long a poll's transaction may take on this bus, its retries included."""
        ...

    def transmit(self, planner: Planner, now: float) -> Any:
        """The next request to send, or :class:`~pkwbus.master.planning.plan.Idle`."""
        ...

    def received(
        self, planner: Planner, request: Any, answer: Any, now: float, busy: float,
        answered: float,
    ) -> None:  # fmt: skip
        """The answer to ``request`` (it held the line ``busy`` seconds, its answer took
        ``answered`` from the request written)."""
        ...

    def lost(self) -> None:
        """The port is gone: what was under way starts afresh."""
        ...

    def leave_out(self, planner: Planner, drive: str, out: bool, now: float) -> None:
        """Send ``drive`` nothing (``out``: in maintenance, already so in the planner: an
        exchange of it that will get no answer ends there), or take it back."""
        ...

    def take_events(self) -> list[Event]: ...
