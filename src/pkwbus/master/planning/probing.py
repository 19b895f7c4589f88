"""A probe job on the wire: the drive's shortest telegram, repeated until an answer comes.

The question of a scan and of a configuration check (:class:`ProbeJob`): is a
drive at this address? The carrier's probe goes out (the telegram a down
drive is probed with); any answer from the drive asked ends it as
:class:`Heard`, with the status word the answer carries, where it has one. A
timeout, a bad telegram or an answer that cannot be read is a try, repeated
up to ``retries`` times, as a read is; a lost port ends it at once. Nothing
is written: a probe carries no parameter request.
"""

from __future__ import annotations

from collections.abc import Callable

from pkwbus.master.planning.answers import ErrorKind, ExchangeResult, Failure
from pkwbus.master.planning.jobs import ProbeJob
from pkwbus.master.planning.outcomes import Heard, LineFailed, Outcome, TimedOut
from pkwbus.master.planning.transaction import Tally

__all__ = ["ProbeJob", "ProbeTransaction", "StatusOf"]

# An answer's status word and main actual value, where it has them (the carrier's).
StatusOf = Callable[[ExchangeResult], tuple[int, int | None] | None]


class ProbeTransaction:
    """Feed it exchange results; it says when the probe is done and how."""

    def __init__(self, telegram: bytes, status: StatusOf, *, retries: int, deadline: float) -> None:
        self.telegram = telegram
        self.status = status
        self.retries = retries
        self.deadline = deadline
        self.tally = Tally()
        self.outcome: Outcome | None = None
        self.waiting = False  # a probe is never answered "not yet"
        self._failures = 0

    def feed(self, result: ExchangeResult, now: float) -> Outcome | None:
        """Account for one exchange; the outcome once the probe is finished."""
        tally = self.tally
        tally.telegrams += 1
        outcome: Outcome | None = None
        if isinstance(result, Failure):
            tally.errors[result.kind] += 1
            if result.kind is ErrorKind.PORT:
                outcome = LineFailed(result.detail)
            else:
                self._failures += 1
                if self._failures > self.retries:
                    last = result.detail or result.kind.value
                    outcome = TimedOut(f"no answer after {self._failures} tries (the last: {last})")
        else:
            tally.busy += result.duration
            said = self.status(result)
            tally.status_word, tally.main_actual = said if said is not None else (None, None)
            outcome = Heard()
        if outcome is None and now >= self.deadline:
            outcome = TimedOut("deadline passed")
        if outcome is not None:
            self.outcome = outcome
        else:
            tally.retries += 1
        return outcome
