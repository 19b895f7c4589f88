"""What a job's outcome becomes in the HTTP API's answer and in the audit log (whose
outcome names an MQTT write's result uses too).

Each is a ``match`` over the closed union :data:`pkwbus.master.planning.outcomes.Outcome`
that ends in ``assert_never``: a new kind of outcome cannot be forgotten here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, assert_never

from pkwbus.master.planning.outcomes import (
    Answered,
    Cancelled,
    Heard,
    LineFailed,
    Mismatch,
    NotSent,
    Outcome,
    Rejected,
    TimedOut,
    unanswered,
)
from pkwbus.master.planning.planner import IN_MAINTENANCE

__all__ = ["AuditOutcome", "HttpFailure", "audit_outcome", "http_failure"]


# ------------------------------------------------------------------ HTTP API


@dataclass(frozen=True, slots=True)
class HttpFailure:
    """The HTTP API's error answer for a job that did not end in an answer."""

    status: int
    kind: str
    message: str
    extra: dict[str, Any] = field(default_factory=dict)


def http_failure(outcome: Outcome, sent: int = 0) -> HttpFailure | None:
    """The API's error answer for ``outcome``; None when the drive answered. ``sent``: how
    many times its request went out."""
    match outcome:
        case Answered() | Heard():
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
            return HttpFailure(504, "timeout", unanswered(reason))
        case LineFailed(reason=reason):
            return HttpFailure(504, "line_error", unanswered(reason))
        case Cancelled(reason=reason) if reason == IN_MAINTENANCE and not sent:
            # Ended, before it went out, by a maintenance that began while it waited:
            # answered as a job for a drive in maintenance is (README "A drive in maintenance").
            return HttpFailure(409, "in_maintenance", f"{reason}: nothing was sent")
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
        case Answered() | Heard():
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
            if reason == IN_MAINTENANCE and not sent:  # ended before it went out
                return AuditOutcome("not_sent", None, reason)
            return AuditOutcome("cancelled", None, reason + note)
        case _:
            assert_never(outcome)
