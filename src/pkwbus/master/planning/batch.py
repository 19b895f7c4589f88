"""Several jobs of one drive in one request, as a state machine without I/O: the polls of a
drive due together, carried where one request takes many parameters (PROFIdrive data record
47, :mod:`pkwbus.master.carriers.record`).

Each job's outcome comes from the one response, as its carrier decodes it: a
value, the drive's refusal, a change done. A transfer that fails, or a
response its carrier cannot take for this request's answer, is tried again,
the same request, up to ``retries`` times; then every job of it ends timed
out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from pkwbus.master.planning.answers import ErrorKind, ExchangeResult, Failure, Reply
from pkwbus.master.planning.outcomes import LineFailed, Outcome, TimedOut
from pkwbus.master.planning.transaction import Tally
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError

__all__ = ["BatchDecoder", "BatchTransaction"]

# A response's data into each job's outcome, in the request's order (its carrier's);
# RemoteProtocolError for a response that is not this request's answer.
BatchDecoder = Callable[[bytes], Sequence[Outcome]]


class BatchTransaction:
    """Feed it exchange results; it says when the request is done, and each job's outcome."""

    def __init__(
        self,
        count: int,
        telegram: bytes,
        decode: BatchDecoder,
        *,
        retries: int,
        deadline: float,
    ) -> None:
        self.count = count
        self.telegram = telegram
        self.decode = decode
        self.retries = retries
        self.deadline = deadline
        self.tally = Tally()
        self.waiting = False
        self.outcome: Outcome | None = None
        self.outcomes: tuple[Outcome, ...] = ()
        self._failures = 0

    def feed(self, result: ExchangeResult, now: float) -> Outcome | None:
        """Account for one transfer; once the request is finished, the first job's
        outcome (each job's is in :attr:`outcomes`)."""
        tally = self.tally
        tally.telegrams += 1
        if isinstance(result, Failure):
            tally.errors[result.kind] += 1
            if result.kind is ErrorKind.PORT:
                return self._end(LineFailed(result.detail))
            return self._try_again(f"no answer ({result.kind.value}: {result.detail})", now)
        if not isinstance(result, Reply):
            raise LocalProtocolError("a request of several parameters answers with a reply")
        tally.busy += result.duration
        try:
            outcomes = tuple(self.decode(result.data))
        except RemoteProtocolError as exc:
            tally.errors[ErrorKind.UNEXPECTED] += 1
            return self._try_again(str(exc), now)
        return self._end(outcomes[0], outcomes)

    def _try_again(self, why: str, now: float) -> Outcome | None:
        self._failures += 1
        if self._failures > self.retries or now >= self.deadline:
            return self._end(TimedOut(f"no parameter response after {self._failures} tries: {why}"))
        tally = self.tally
        tally.retries += 1
        return None

    def _end(self, outcome: Outcome, outcomes: tuple[Outcome, ...] | None = None) -> Outcome:
        self.outcome = outcome
        self.outcomes = outcomes if outcomes is not None else (outcome,) * self.count
        return outcome
