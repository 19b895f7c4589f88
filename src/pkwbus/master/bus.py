"""What a line's runner drives: the port of its bus and the wire that speaks it.

:class:`Port` is the I/O of one line (one request at a time); :class:`Wire` is
a kind of line, a few pure calls about what goes out and what came back
(:mod:`pkwbus.master.wires`). Both are generic over the line's requests and
answers (FC and USS: a :class:`~pkwbus.master.planning.plan.Send` and its
:data:`~pkwbus.master.planning.answers.ExchangeResult`; PROFIBUS DP: an FDL
frame and its answer), so that a runner given the port of one bus and the wire
of another does not type-check. The runner (:mod:`pkwbus.master.runner`) is
given the two apart and is the only one that calls them; a wire never holds
its port.
"""

from __future__ import annotations

from typing import Protocol, TypeVar

from pkwbus.link import Link, PortError
from pkwbus.master.events import Event
from pkwbus.master.planning.plan import Idle
from pkwbus.master.planning.planner import Planner

__all__ = ["Done", "LineRefused", "Port", "Wire"]

# A port consumes its requests and produces its answers (through ``done``).
_PortRequest = TypeVar("_PortRequest", contravariant=True)
_PortAnswer = TypeVar("_PortAnswer", covariant=True)
# A wire makes the requests and is given them back with their answers.
_WireRequest = TypeVar("_WireRequest")
_WireAnswer = TypeVar("_WireAnswer", contravariant=True)
_DoneAnswer = TypeVar("_DoneAnswer", contravariant=True)


class Done(Protocol[_DoneAnswer]):
    """What a port calls once with a request's answer, or the exception that ended it.

    A protocol rather than a ``Callable`` alias: mypy infers a runner's answer type from
    ``Done[Answer]`` whole, where from a ``Callable`` of a union it would join the union's
    members (to ``object``) and find no type that fits the wire."""

    def __call__(self, answer: _DoneAnswer | BaseException, /) -> None: ...


class LineRefused(PortError):
    """The line cannot be used though its port is open (another master runs it): the port
    is given up, and opened again at back-off."""


class Port(Protocol[_PortRequest, _PortAnswer]):
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

    def start(self, request: _PortRequest, done: Done[_PortAnswer]) -> None:
        """Send ``request``; ``done`` gets its answer, or the exception that ended it."""
        ...

    async def close(self) -> None:
        """The line stops: what the bus asks first (a DP master clears its slaves), then
        the port closes."""
        ...


class Wire(Protocol[_WireRequest, _WireAnswer]):
    """A kind of line: pure calls about what goes out and what came back; no runner and no
    port (a fact of its port it needs is given to it when it is made)."""

    def poll_deadline(self, retries: int) -> float:
        """How long a poll's transaction may take on this bus, its retries included."""
        ...

    def transmit(self, planner: Planner, now: float) -> _WireRequest | Idle:
        """The next request to send, or :class:`~pkwbus.master.planning.plan.Idle`."""
        ...

    def received(
        self, planner: Planner, request: _WireRequest, answer: _WireAnswer, now: float,
        busy: float, answered: float,
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
