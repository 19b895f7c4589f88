"""One PKW job on the wire as a state machine without I/O; and one probe (at the end).

The rule is the SINAMICS G120 CU240B-2/CU240E-2 Operating Instructions'
(section 6.3, "Communication via PROFIBUS").

The same request goes out again until the matching answer arrives or the
deadline passes; on a cyclic channel (a PROFIBUS PPO) the request stays in
every PPO-write, and every answer comes here to be judged (the one rule of
every bus). A non-matching answer (AK 0, a stale answer, another PNU) is
"not yet": counted as unexpected, never a failure. Timeouts, bad telegrams
and answers that cannot be read are retried up to ``retries`` times. A change
acknowledged with another value than the one sent ends at once as
:class:`Mismatch` (a repeat would write that value again), unless the answer
is the drive's previous answer repeated (``stale``: a lagging drive still
telling its last one). A reply's bytes are decoded once, by the decoder its
carrier gave the transaction (:mod:`pkwbus.master.planning.carrier`).

Several jobs of one drive in one request (:class:`BatchTransaction`): the polls of a
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
from dataclasses import dataclass, field
from operator import itemgetter

from pkwbus.master.planning.answers import ErrorKind, ExchangeResult, Failure, PkwAnswer, Reply
from pkwbus.master.planning.outcomes import (
    Answered,
    Heard,
    LineFailed,
    Mismatch,
    Outcome,
    Rejected,
    TimedOut,
)
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Dialect

__all__ = [
    "BatchDecoder",
    "BatchTransaction",
    "Decoder",
    "PkwTransaction",
    "ProbeTransaction",
    "StatusOf",
    "Tally",
]

# A reply's data and duration into the PKW answer it carries (its carrier's, decoded once).
Decoder = Callable[[bytes, float], PkwAnswer]


@dataclass(slots=True)
class Tally:
    """What a job's exchanges cost, for the metrics, and what its latest answer was."""

    telegrams: int = 0
    retries: int = 0
    # Exchanges without a usable answer, by kind (a dict: one Tally is made per job).
    errors: dict[ErrorKind, int] = field(default_factory=dict)
    # The status word and main actual value of the latest reply; None when it carried
    # none or could not be split (never an earlier reply's, re-stamped as new).
    status_word: int | None = None
    main_actual: int | None = None
    busy: float = 0.0
    # The latest exchange's PKW answer as decoded, and its length in words (None when
    # that exchange brought none): what it tells of the drive's PKW length.
    response: pkw.PkwResponse | None = None
    answer_words: int | None = None
    # The request as it went out (empty where its carrier builds it in the wire).
    sent: bytes = b""

    def count_error(self, kind: ErrorKind) -> None:
        """One more exchange without a usable answer, of ``kind``."""
        errors = self.errors
        errors[kind] = errors.get(kind, 0) + 1


class PkwTransaction:
    """Feed it exchange results; it says when the job is done and how."""

    __slots__ = (
        "_failures", "answer_pkw", "deadline", "decode", "dialect", "every_cycle", "outcome",
        "request", "response", "retries", "stale", "tally", "telegram", "waiting",
    )  # fmt: skip

    def __init__(
        self,
        dialect: Dialect,
        request: pkw.PkwRequest,
        telegram: bytes,
        decode: Decoder,
        *,
        retries: int,
        deadline: float,
        stale: bytes | None = None,  # the PKW bytes of the drive's answer before this job
        every_cycle: bool = False,
    ) -> None:
        self.dialect = dialect
        # Its channel answers every cycle (a PPO's PKW slot): "not yet" is its way of
        # working, neither an unexpected answer nor a try (its carrier's to say).
        self.every_cycle = every_cycle
        self.request = request
        self.telegram = telegram  # the request as it goes out (empty: its carrier builds it)
        self.decode = decode
        self.stale = stale
        # The latest answer that decoded: its PKW bytes and what they say.
        self.answer_pkw: bytes | None = None
        self.response: pkw.PkwResponse | None = None
        self.retries = retries
        self.deadline = deadline
        self.tally = Tally(sent=telegram)
        self._failures = 0
        self.outcome: Outcome | None = None
        self.waiting = False  # last answer was "not yet"

    def feed(self, result: ExchangeResult, now: float) -> Outcome | None:
        """Account for one exchange; the outcome once the job is finished."""
        tally = self.tally
        tally.telegrams += 1
        self.answer_pkw = self.response = tally.response = tally.answer_words = None
        if isinstance(result, Failure):
            outcome = self._on_failure(result)
        else:
            answer = self.decode(result.data, result.duration)
            tally.busy += answer.duration
            tally.status_word, tally.main_actual = answer.status_word, answer.main_actual
            outcome = self._on(answer)
        if outcome is None and now >= self.deadline:
            outcome = TimedOut("deadline passed" + self._last_error())
        if outcome is not None:
            self.outcome = outcome
        elif not (self.every_cycle and self.response is not None):
            tally.retries += 1
        return outcome

    def _last_error(self) -> str:
        if not self.tally.errors:
            return ""
        most = sorted(self.tally.errors.items(), key=itemgetter(1), reverse=True)
        kinds = ", ".join(f"{n} {k.value}" for k, n in most)
        return f" ({kinds})"

    def _on(self, came: PkwAnswer) -> Outcome | None:
        response, answer = came.response, came.pkw
        if response is None:
            # The right drive, but an answer that cannot be read (a block too short for
            # the answer, another dialect's): a try of the job's retries, not "not yet"
            # forever.
            self.tally.count_error(ErrorKind.UNEXPECTED)
            self.waiting = True
            self._failures += 1
            if self._failures > self.retries:
                return TimedOut(
                    f"no answer that can be read after {self._failures} tries: {came.why}"
                )
            return None
        self.answer_pkw, self.response = answer, response
        self.tally.response, self.tally.answer_words = response, len(answer) // 2
        verdict = pkw.judge(self.request, response, self.dialect)
        if answer == self.stale and isinstance(response, pkw.Rejection):
            verdict = pkw.Verdict.NOT_YET  # the read's rejection repeated, not the change's
        if came.earlier and verdict is pkw.Verdict.MISMATCH:
            verdict = pkw.Verdict.NOT_YET  # no AK 0 seen first: an earlier answer, maybe
        if verdict is pkw.Verdict.ANSWER:
            self.waiting = False
            if isinstance(response, pkw.Rejection):
                return Rejected(response.fault, response.text, response.short)
            return Answered(response)
        mismatch = verdict is pkw.Verdict.MISMATCH and answer != self.stale
        if mismatch and isinstance(response, pkw.ValueResponse):
            self.waiting = False
            return Mismatch(self.request.value, response.raw, response)
        if not self.every_cycle:
            self.tally.count_error(ErrorKind.UNEXPECTED)
        self.waiting = True
        return None

    def _on_failure(self, failure: Failure) -> Outcome | None:
        self.tally.count_error(failure.kind)
        self.waiting = False
        if failure.kind is ErrorKind.PORT:
            return LineFailed(failure.detail)
        if failure.kind is ErrorKind.UNEXPECTED:
            return None  # a garbled answer from the right drive: not yet
        self._failures += 1
        if self._failures > self.retries:
            return TimedOut(f"no valid answer after {self._failures} tries" + self._last_error())
        return None


# ---------------------------------------------------------------- a probe
# A probe job on the wire: the drive's shortest telegram, repeated until an answer comes.
#
# The question of a scan and of a configuration check (:class:`ProbeJob`): is a
# drive at this address? The carrier's probe goes out (the telegram a down
# drive is probed with); any answer from the drive asked ends it as
# :class:`Heard`, with the status word the answer carries, where it has one. A
# timeout, a bad telegram or an answer that cannot be read is a try, repeated
# up to ``retries`` times, as a read is; a lost port ends it at once. Nothing
# is written: a probe carries no parameter request.

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
            tally.count_error(result.kind)
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
            tally.count_error(result.kind)
            if result.kind is ErrorKind.PORT:
                return self._end(LineFailed(result.detail))
            return self._try_again(f"no answer ({result.kind.value}: {result.detail})", now)
        if not isinstance(result, Reply):
            raise LocalProtocolError("a request of several parameters answers with a reply")
        tally.busy += result.duration
        try:
            outcomes = tuple(self.decode(result.data))
        except RemoteProtocolError as exc:
            tally.count_error(ErrorKind.UNEXPECTED)
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
