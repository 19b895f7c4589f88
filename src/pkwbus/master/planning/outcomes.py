"""What a finished job came to: a closed union, and its ``outcome`` metric label.

``Outcome`` is a closed union: every mapping of it is a ``match`` that ends in
``assert_never``, so a new kind of outcome cannot be forgotten by one of them.
The ``outcome`` label of ``pkwbus_jobs_total`` is here; the HTTP API's error
answer and the audit log's columns live with the service
(:mod:`pkwbus.service.writes.outcomes`), the exit code of ``pkwbus
read``/``write`` with the commands (:mod:`pkwbus.commands.answers`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import assert_never

from pkwbus.protocol import pkw

__all__ = [
    "Answered",
    "Cancelled",
    "Heard",
    "JobOutcome",
    "LineFailed",
    "Mismatch",
    "NotSent",
    "Outcome",
    "Rejected",
    "TimedOut",
    "metric_label",
    "unanswered",
]


@dataclass(frozen=True, slots=True)
class Answered:
    """The drive answered the request: a value, a text, a description, a count."""

    response: pkw.PkwResponse


@dataclass(frozen=True, slots=True)
class Heard:
    """The drive answered a probe (the shortest telegram it answers): it is there. Its
    status word, where the answer has one, is in the job's tally."""


@dataclass(frozen=True, slots=True)
class Rejected:
    """The drive refused the request (AK 7 and its fault number)."""

    fault: int | None
    text: str
    short: str


@dataclass(frozen=True, slots=True)
class TimedOut:
    """No matching answer: retries used up or the deadline passed."""

    reason: str


@dataclass(frozen=True, slots=True)
class LineFailed:
    """The port is not there."""

    reason: str


@dataclass(frozen=True, slots=True)
class Mismatch:
    """The drive acknowledged the change with another value than the one sent: it took
    something else. Never repeated: a repeat would write that again."""

    sent: int
    answered: int
    response: pkw.PkwResponse


@dataclass(frozen=True, slots=True)
class NotSent:
    """The request was not sent: what the drive's answers told forbids it (its PKW length
    contradicts the configuration, or a word's place in PWE is not known)."""

    reason: str


@dataclass(frozen=True, slots=True)
class Cancelled:
    """The job never finished: the service stopped or the job was withdrawn."""

    reason: str


Outcome = Answered | Heard | Rejected | Mismatch | NotSent | TimedOut | LineFailed | Cancelled


# ------------------------------------------------------------------ metrics


class JobOutcome(enum.StrEnum):
    """The ``outcome`` label of ``pkwbus_jobs_total``."""

    OK = "ok"
    REJECTED = "rejected"
    TIMEOUT = "timeout"
    CANCELLED = "cancelled"
    MISMATCH = "mismatch"


def unanswered(reason: str) -> str:
    """What a job that got no valid answer says: ``no valid answer: REASON``, said once
    where the reason says it already ("no valid answer after 3 tries")."""
    return reason if reason.startswith("no valid answer") else f"no valid answer: {reason}"


def metric_label(outcome: Outcome) -> JobOutcome:
    """The ``outcome`` label of ``pkwbus_jobs_total``."""
    match outcome:
        case Answered() | Heard():
            return JobOutcome.OK
        case Rejected():
            return JobOutcome.REJECTED
        case Mismatch():
            return JobOutcome.MISMATCH
        case TimedOut() | LineFailed():
            return JobOutcome.TIMEOUT
        case Cancelled() | NotSent():
            return JobOutcome.CANCELLED
        case _:
            assert_never(outcome)
