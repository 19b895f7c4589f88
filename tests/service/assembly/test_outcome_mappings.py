"""Every outcome of a job has one metric label, one API answer, one audit row, one exit code."""

from __future__ import annotations

from typing import get_args

import pytest

from pkwbus.commands.exits import Exit
from pkwbus.commands.failures import command_failure
from pkwbus.master.planning.outcomes import (
    Answered,
    Cancelled,
    Heard,
    JobOutcome,
    LineFailed,
    Mismatch,
    NotSent,
    Outcome,
    Rejected,
    TimedOut,
    metric_label,
)
from pkwbus.protocol import pkw
from pkwbus.service.writes.outcomes import audit_outcome, http_failure

ANSWERED = Answered(pkw.ValueResponse(1, 1613, 0, 5, pkw.Width.WORD))
MISMATCH = Mismatch(1234, 0, pkw.ValueResponse(1, 1120, 0, 0, pkw.Width.WORD))
EXAMPLES: list[Outcome] = [
    ANSWERED,
    Heard(),
    Rejected(17, "not while running", "running"),
    MISMATCH,
    NotSent("the drive answers with a PKW length of 127 (variable), the configuration says 4"),
    TimedOut("deadline passed"),
    LineFailed("no port"),
    Cancelled("the service is stopping"),
]


def test_the_examples_cover_the_union() -> None:
    assert {type(o) for o in EXAMPLES} == set(get_args(Outcome))


@pytest.mark.parametrize("outcome", EXAMPLES, ids=lambda o: type(o).__name__)
def test_only_an_answer_is_a_success_everywhere(outcome: Outcome) -> None:
    answered = isinstance(outcome, Answered | Heard)  # a probe's answer is its success
    assert (metric_label(outcome) is JobOutcome.OK) == answered
    assert (http_failure(outcome) is None) == answered
    assert (command_failure(outcome) is None) == answered
    assert (audit_outcome(outcome, sent=1).outcome == "ok") == answered


def test_a_rejection_carries_the_drives_fault() -> None:
    rejected = Rejected(17, "not while running", "running")
    http = http_failure(rejected)
    assert http is not None
    assert (http.status, http.kind, http.extra["fault"]) == (409, "rejected", 17)
    command = command_failure(rejected)
    assert command is not None
    assert (command.code, command.fault) == (Exit.REJECTED, 17)
    assert command.message == "fault 17: not while running"
    audit = audit_outcome(rejected, sent=1)
    assert (audit.outcome, audit.fault, audit.detail) == ("rejected", 17, "not while running")


@pytest.mark.parametrize(
    ("outcome", "status", "kind"),
    [
        (TimedOut("x"), 504, "timeout"),
        (LineFailed("x"), 504, "line_error"),
        (Cancelled("x"), 503, "cancelled"),
    ],
)
def test_no_answer_in_the_api(outcome: Outcome, status: int, kind: str) -> None:
    failure = http_failure(outcome)
    assert failure is not None
    assert (failure.status, failure.kind) == (status, kind)
    assert metric_label(outcome) is (
        JobOutcome.CANCELLED if isinstance(outcome, Cancelled) else JobOutcome.TIMEOUT
    )


def test_an_unanswered_write_says_whether_it_went_out() -> None:
    assert audit_outcome(TimedOut("port gone"), sent=0).outcome == "not_sent"
    sent = audit_outcome(TimedOut("deadline passed"), sent=3)
    assert sent.outcome == "timeout"
    assert sent.detail is not None and "3 times and may have been applied" in sent.detail
    cancelled = audit_outcome(Cancelled("stopping"), sent=0)
    assert (cancelled.outcome, cancelled.detail) == ("cancelled", "stopping")


def test_a_mismatch_is_its_own_outcome_everywhere() -> None:
    """A write the drive acknowledged with another value: not a rejection, not a timeout."""
    assert metric_label(MISMATCH) is JobOutcome.MISMATCH
    http = http_failure(MISMATCH)
    assert http is not None
    assert (http.status, http.kind, http.extra) == (409, "mismatch", {"sent": 1234, "answered": 0})
    command = command_failure(MISMATCH)
    assert command is not None and command.code is Exit.MISMATCH and command.kind == "mismatch"
    audit = audit_outcome(MISMATCH, sent=1)
    assert audit.outcome == "mismatch" and audit.detail is not None and "1234" in audit.detail


def test_a_change_not_sent_says_so_everywhere() -> None:
    unsent = NotSent("the configuration says 4")
    http = http_failure(unsent)
    assert http is not None and (http.status, http.kind) == (409, "not_sent")
    command = command_failure(unsent)
    assert command is not None and command.code is Exit.BAD_INPUT
    assert audit_outcome(unsent, sent=0).outcome == "not_sent"
