"""One PKW job on the wire as a state machine without I/O.

The rule is the SINAMICS G120 CU240B-2/CU240E-2 Operating Instructions'
(section 6.3, "Communication via PROFIBUS").

The same request bytes go out again until the matching answer arrives or
the deadline passes; on a cyclic channel (a PROFIBUS PPO) the request stays in
every PPO-write, and every answer comes here to be judged (the one rule of
every bus). A non-matching answer (AK 0, a stale answer, another
PNU) is "not yet": counted as unexpected, never a failure. Timeouts and bad
telegrams are retried up to ``retries`` times. A change acknowledged with
another value than the one sent ends at once as :class:`Mismatch` (a repeat
would write that value again), unless the answer is the drive's previous
answer repeated (``stale``: a lagging drive still telling its last one).
"""

from __future__ import annotations

import enum
from collections import Counter
from dataclasses import dataclass, field

from pkwbus.master.planning.outcomes import (
    Answered,
    LineFailed,
    Mismatch,
    Outcome,
    Rejected,
    TimedOut,
)
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.serial.telegram import split_block

__all__ = [
    "Answered",
    "ErrorKind",
    "ExchangeResult",
    "Failure",
    "LineFailed",
    "Mismatch",
    "Outcome",
    "PkwAnswer",
    "PkwTransaction",
    "Rejected",
    "ResponseTelegram",
    "Tally",
    "TimedOut",
]


class ErrorKind(enum.StrEnum):
    """Why one exchange produced no usable answer (the metric's ``kind`` label)."""

    TIMEOUT = "timeout"
    CHECKSUM = "checksum"
    LENGTH = "length"
    ADDRESS = "address"
    UNEXPECTED = "unexpected"
    PORT = "port"


@dataclass(frozen=True, slots=True)
class ResponseTelegram:
    """A valid telegram from the addressed drive."""

    adr: int
    data: bytes
    duration: float


@dataclass(frozen=True, slots=True)
class PkwAnswer:
    """A PKW answer decoded once where it came in, with the process data beside it: what a
    wire that decodes its own frames gives (a PROFIBUS PPO-read), instead of bytes."""

    response: pkw.PkwResponse
    pkw: bytes  # as sent, for a stale answer's comparison (empty where none is kept)
    status_word: int | None
    main_actual: int | None
    duration: float
    # A cyclic channel (a PPO) answers every cycle: "not yet" is its way of working, not
    # an unexpected answer nor a repeat of the request.
    cyclic: bool = False
    # No AK 0 was seen since the request went in: it may still answer an earlier one.
    earlier: bool = False


@dataclass(frozen=True, slots=True)
class Failure:
    kind: ErrorKind
    detail: str = ""
    # An answer from the right drive that cannot be read (a PPO-read whose PKW words are
    # no answer of the dialect): a try of the job's retries, as a telegram that does not
    # decode is on FC and USS, not "not yet" forever.
    unreadable: bool = False


ExchangeResult = ResponseTelegram | PkwAnswer | Failure


@dataclass
class Tally:
    """What a job's exchanges cost, for the metrics, and what its latest answer was."""

    telegrams: int = 0
    retries: int = 0
    errors: Counter[ErrorKind] = field(default_factory=Counter)
    # The status word and main actual value of the latest reply; None when it carried
    # none or could not be split (never an earlier reply's, re-stamped as new).
    status_word: int | None = None
    main_actual: int | None = None
    busy: float = 0.0
    # The latest exchange's PKW answer as decoded, and its length in words (None when
    # that exchange brought none): what it tells of the drive's PKW length.
    response: pkw.PkwResponse | None = None
    answer_words: int | None = None


class PkwTransaction:
    """Feed it exchange results; it says when the job is done and how."""

    def __init__(
        self,
        target: DriveTarget,
        request: pkw.PkwRequest,
        *,
        retries: int,
        deadline: float,
        telegram: bytes | None = None,  # ``target.telegram(request)``, when already built
        stale: bytes | None = None,  # the PKW bytes of the drive's answer before this job
    ) -> None:
        self.target = target
        self.request = request
        self.stale = stale
        # The latest answer that decoded: its PKW bytes and what they say.
        self.answer_pkw: bytes | None = None
        self.response: pkw.PkwResponse | None = None
        self.telegram = telegram if telegram is not None else target.telegram(request)
        self.retries = retries
        self.deadline = deadline
        self.tally = Tally()
        self._failures = 0
        self.outcome: Outcome | None = None
        self.waiting = False  # last answer was "not yet"

    def feed(self, result: ExchangeResult, now: float) -> Outcome | None:
        """Account for one exchange; the outcome once the job is finished."""
        tally = self.tally
        tally.telegrams += 1
        self.answer_pkw = self.response = tally.response = tally.answer_words = None
        if isinstance(result, ResponseTelegram):
            tally.busy += result.duration
            outcome = self._on_reply(result)
        elif isinstance(result, Failure):
            outcome = self._on_failure(result)
        else:  # decoded where it came in
            tally.busy += result.duration
            tally.status_word, tally.main_actual = result.status_word, result.main_actual
            outcome = self._on(result.response, result.pkw, result)
        if outcome is None and now >= self.deadline:
            outcome = TimedOut("deadline passed" + self._last_error())
        if outcome is not None:
            self.outcome = outcome
        elif not (isinstance(result, PkwAnswer) and result.cyclic):
            tally.retries += 1
        return outcome

    def _last_error(self) -> str:
        if not self.tally.errors:
            return ""
        kinds = ", ".join(f"{n} {k.value}" for k, n in self.tally.errors.most_common())
        return f" ({kinds})"

    def _on_reply(self, reply: ResponseTelegram) -> Outcome | None:
        """A telegram's data split by the drive's shape, its PKW part decoded once."""
        target = self.target
        tally = self.tally
        tally.status_word = tally.main_actual = None
        try:
            block = split_block(reply.data, target.response_shape(len(reply.data)))
            tally.status_word = block.status_word
            tally.main_actual = block.main_actual
            response = pkw.decode_response(block.pkw, target.dialect, target.ind_layout)
        except RemoteProtocolError as exc:
            # The right drive, but an answer that cannot be read (a block too short for
            # the answer, say): a try of the job's retries, not "not yet" forever.
            self.tally.errors[ErrorKind.UNEXPECTED] += 1
            self.waiting = True
            self._failures += 1
            if self._failures > self.retries:
                return TimedOut(f"no answer that can be read after {self._failures} tries: {exc}")
            return None
        return self._on(response, block.pkw)

    def _on(
        self, response: pkw.PkwResponse, answer: bytes, came: PkwAnswer | None = None
    ) -> Outcome | None:
        self.answer_pkw, self.response = answer, response
        self.tally.response, self.tally.answer_words = response, len(answer) // 2
        verdict = pkw.judge(self.request, response, self.target.dialect)
        if answer == self.stale and isinstance(response, pkw.Rejection):
            verdict = pkw.Verdict.NOT_YET  # the read's rejection repeated, not the change's
        if came is not None and came.earlier and verdict is pkw.Verdict.MISMATCH:
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
        if came is None or not came.cyclic:
            self.tally.errors[ErrorKind.UNEXPECTED] += 1
        self.waiting = True
        return None

    def _on_failure(self, failure: Failure) -> Outcome | None:
        self.tally.errors[failure.kind] += 1
        self.waiting = False
        if failure.kind is ErrorKind.PORT:
            return LineFailed(failure.detail)
        if failure.kind is ErrorKind.UNEXPECTED and not failure.unreadable:
            return None  # a garbled answer from the right drive: not yet
        self._failures += 1
        if failure.unreadable and self._failures > self.retries:
            self.waiting = True
            return TimedOut(f"no answer that can be read after {self._failures} tries: "
                            f"{failure.detail}")  # fmt: skip
        if self._failures > self.retries:
            return TimedOut(f"no valid answer after {self._failures} tries" + self._last_error())
        return None
