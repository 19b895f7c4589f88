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
    "Mismatch",
    "NotSent",
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


Outcome = Answered | Rejected | Mismatch | NotSent | TimedOut | LineFailed | Cancelled


# ------------------------------------------------------------------ metrics


class JobOutcome(enum.StrEnum):
    """The ``outcome`` label of ``pkwbus_jobs_total``."""

    OK = "ok"
    REJECTED = "rejected"
    TIMEOUT = "timeout"
    CANCELLED = "cancelled"
    MISMATCH = "mismatch"


def metric_label(outcome: Outcome) -> JobOutcome:
    """The ``outcome`` label of ``pkwbus_jobs_total``."""
    match outcome:
        case Answered():
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
        case Mismatch(sent=sent, answered=answered):
            return HttpFailure(
                409,
                "mismatch",
                f"the drive acknowledged the write with raw {answered}, not the {sent} sent: "
                "it holds another value than asked (not repeated)",
                {"sent": sent, "answered": answered},
            )
        case NotSent(reason=reason):
            return HttpFailure(409, "not_sent", f"nothing was sent: {reason}")
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
        case Mismatch(sent=sent_raw, answered=answered):
            detail = f"the drive answered raw {answered}, not the {sent_raw} sent"
            return AuditOutcome("mismatch", None, detail)
        case NotSent(reason=reason):
            return AuditOutcome("not_sent", None, reason)
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
        case Mismatch(sent=sent, answered=answered):
            message = (
                f"the drive answered raw {answered}, not the {sent} written: it holds another value"
            )
            return CommandFailure(Exit.MISMATCH, "mismatch", message)
        case NotSent(reason=reason):
            return CommandFailure(Exit.BAD_INPUT, "not_sent", f"nothing was sent: {reason}")
        case TimedOut(reason=reason) | LineFailed(reason=reason) | Cancelled(reason=reason):
            return CommandFailure(Exit.NO_ANSWER, "timeout", f"no valid answer: {reason}")
        case _:
            assert_never(outcome)
