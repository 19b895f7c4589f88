"""How ``pkwbus read``, ``write`` and ``describe`` end for an outcome that is not an answer:
the exit code (README.md's table), a kind for ``--json`` and a message.

A ``match`` over the closed union :data:`pkwbus.master.planning.outcomes.Outcome` that ends in
``assert_never``: a new kind of outcome cannot be forgotten here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import assert_never

from pkwbus.commands.exits import Exit
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

__all__ = ["CommandFailure", "command_failure"]


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
        case Answered() | Heard():
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
            return CommandFailure(Exit.NO_ANSWER, "timeout", unanswered(reason))
        case _:
            assert_never(outcome)
