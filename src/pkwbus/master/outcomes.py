"""What a finished job came to, and everything that outcome becomes, side by side.

``Outcome`` is a closed union: every mapping below is a ``match`` over it that
ends in ``assert_never``, so a new kind of outcome cannot be forgotten by one
of them. The mappings are the ``outcome`` label of ``pkwbus_jobs_total``, the
HTTP API's error answer, the audit log's outcome of a write, and the exit code
of ``pkwbus read``/``write``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, assert_never

from pkwbus.exits import Exit
from pkwbus.protocol import pkw

__all__ = [
    "Answered",
    "AuditOutcome",
    "Cancelled",
    "CommandFailure",
    "HttpFailure",
    "JobOutcome",
    "LineFailed",
    "Outcome",
    "Rejected",
    "TimedOut",
    "audit_outcome",
    "command_failure",
    "http_failure",
    "metric_label",
]


@dataclass(frozen=True, slots=True)
class Answered:
    """The drive answered the request: a value, a text, a description, a count."""

    response: pkw.PkwResponse


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
class Cancelled:
    """The job never finished: the service stopped or the job was withdrawn."""

    reason: str


Outcome = Answered | Rejected | TimedOut | LineFailed | Cancelled


# ------------------------------------------------------------------ metrics


class JobOutcome(enum.StrEnum):
    """The ``outcome`` label of ``pkwbus_jobs_total``."""

    OK = "ok"
    REJECTED = "rejected"
    TIMEOUT = "timeout"
    CANCELLED = "cancelled"


def metric_label(outcome: Outcome) -> JobOutcome:
    """The ``outcome`` label of ``pkwbus_jobs_total``."""
    match outcome:
        case Answered():
            return JobOutcome.OK
        case Rejected():
            return JobOutcome.REJECTED
        case TimedOut() | LineFailed():
            return JobOutcome.TIMEOUT
        case Cancelled():
            return JobOutcome.CANCELLED
        case _:
            assert_never(outcome)


# ------------------------------------------------------------------ HTTP API


@dataclass(frozen=True, slots=True)
class HttpFailure:
    """The HTTP API's error answer for a job that did not end in an answer."""

    status: int
    kind: str
    message: str
    extra: dict[str, Any] = field(default_factory=dict)


def http_failure(outcome: Outcome) -> HttpFailure | None:
    """The API's error answer for ``outcome``; None when the drive answered."""
    match outcome:
        case Answered():
            return None
        case Rejected(fault=fault, text=text):
            return HttpFailure(
                409,
                "rejected",
                f"the drive rejected the request: {text}",
                {"fault": fault, "text": text},
            )
        case TimedOut(reason=reason):
            return HttpFailure(504, "timeout", f"no valid answer: {reason}")
        case LineFailed(reason=reason):
            return HttpFailure(504, "line_error", f"no valid answer: {reason}")
        case Cancelled(reason=reason):
            return HttpFailure(503, "cancelled", reason)
        case _:
            assert_never(outcome)


# ------------------------------------------------------------------ audit log


@dataclass(frozen=True, slots=True)
class AuditOutcome:
    """A write's ``outcome``, ``fault`` and ``detail`` columns in the audit log."""

    outcome: str
    fault: int | None = None
    detail: str | None = None


def audit_outcome(outcome: Outcome, sent: int) -> AuditOutcome:
    """A write's audit columns; ``sent``: how many times its request went out."""
    note = f"; the request went out {sent} times and may have been applied" if sent else ""
    match outcome:
        case Answered():
            return AuditOutcome("ok")
        case Rejected(fault=fault, text=text):
            return AuditOutcome("rejected", fault, text)
        case TimedOut(reason=reason) | LineFailed(reason=reason):
            if not sent:  # refused by the line before it went out
                return AuditOutcome("not_sent", None, reason)
            return AuditOutcome("timeout", None, reason + note)
        case Cancelled(reason=reason):
            return AuditOutcome("cancelled", None, reason + note)
        case _:
            assert_never(outcome)


# ------------------------------------------------------------------ commands


@dataclass(frozen=True, slots=True)
class CommandFailure:
    """How ``pkwbus read``/``write`` end when the drive gave no answer to use."""

    code: Exit
    kind: str
    message: str
    fault: int | None = None


def command_failure(outcome: Outcome) -> CommandFailure | None:
    """The exit code, kind and message for ``outcome``; None when the drive answered."""
    match outcome:
        case Answered():
            return None
        case Rejected(fault=fault, text=text):
            code = "" if fault is None else f"fault {fault}: "
            return CommandFailure(Exit.REJECTED, "rejected", f"{code}{text}", fault)
        case TimedOut(reason=reason) | LineFailed(reason=reason) | Cancelled(reason=reason):
            return CommandFailure(Exit.NO_ANSWER, "timeout", f"no valid answer: {reason}")
        case _:
            assert_never(outcome)
