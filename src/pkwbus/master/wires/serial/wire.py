"""FC and USS lines under the runner: one exchange at a time, as the planner chooses them.

Pure calls, holding no runner and no port (:class:`~pkwbus.master.runner.Wire`): the next
request is the planner's next action; an answer goes to the planner as it
came (its carrier decodes it, once), and its cost goes on the stream as an
:class:`~pkwbus.master.events.Exchanged`. The line itself
(:class:`~pkwbus.master.wires.serial.port.TelegramPort`) is the port the runner
drives beside it; the wire is given only its answer timeout, when it is made.
"""

from __future__ import annotations

from pkwbus.master.events import Event, Exchanged
from pkwbus.master.planning.answers import ExchangeResult, Failure, Reply
from pkwbus.master.planning.plan import Action, Send
from pkwbus.master.planning.planner import Planner

__all__ = ["ExchangeWire"]


class ExchangeWire:
    """The :class:`~pkwbus.master.runner.Wire` of an FC or USS line whose port waits
    ``timeout`` seconds for an answer (its :attr:`TelegramPort.timeout`)."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self._events: list[Event] = []

    def poll_deadline(self, retries: int) -> float:
        """Long enough for the retries and a lagging answer."""
        return 4 * (retries + 1) * self.timeout

    def transmit(self, planner: Planner, now: float) -> Action:
        return planner.next_action(now)

    def received(
        self, planner: Planner, request: Send, answer: ExchangeResult, now: float, busy: float,
        answered: float,
    ) -> None:  # fmt: skip
        if isinstance(answer, Failure):
            self._events.append(Exchanged(request.drive, answer.kind, busy))
        else:
            took = answer.duration if isinstance(answer, Reply) else answered
            self._events.append(Exchanged(request.drive, None, busy, took))
        planner.exchanged(request, answer, now)

    def lost(self) -> None:
        """The exchange in flight ends in the line's own loss callback."""

    def leave_out(self, planner: Planner, drive: str, out: bool, now: float) -> None:
        """Nothing to do: the planner gives a drive in maintenance no exchange (one that
        is out ends at its answer or timeout, as every exchange)."""

    def take_events(self) -> list[Event]:
        events, self._events = self._events, []
        return events
