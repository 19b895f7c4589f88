"""How a change goes out: first a read of the same parameter, then the change, if it may.

The read first does two things:

- A drive may answer a new request with its previous answer repeated while
  it works on it (USS specification and the SINAMICS manuals: the master
  repeats a request until the matching answer comes). With the parameter
  just read, that previous answer is known, so a repeat of it is "not yet",
  and any other positive answer with another value than the one sent is the
  drive holding something else: :class:`Mismatch` at once, never repeated.
- A word travels in PWE2 with 4 fixed PKW words and in PWE1 with a variable
  length (USS specification, part C, 4.1.2; SINAMICS G120X Operating
  Instructions, "USS parameter channel"): sent with the wrong one, the drive
  takes another value. The read's answer tells a USS drive's length where it
  is learned (``pkw_words: auto``; :mod:`pkwbus.protocol.pkw_length`), and
  nothing is changed on a drive whose answers contradict the configured
  length, until the two agree.

A PROFIBUS PKW slot waits for AK 0 before each job instead (no stale answer
can be taken), so there the change goes out at once.
"""

from __future__ import annotations

from pkwbus.master.drive_plan import Active, DrivePlan
from pkwbus.master.jobs import Job
from pkwbus.master.outcomes import Cancelled, LineFailed, NotSent, Outcome, TimedOut
from pkwbus.master.plan import Finished, Send
from pkwbus.master.transaction import PkwTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw_fields import Width
from pkwbus.protocol.pkw_length import Gate, shown

__all__ = ["after_read", "gate_write"]


def _gate(d: DrivePlan, request: pkw.PkwRequest) -> Gate:
    if d.pkw is None or (not request.is_write and not request.text):
        return Gate.SEND
    return d.pkw.gate(
        word=request.width is Width.WORD and not request.text, text=bool(request.text)
    )


def _refusal(d: DrivePlan) -> str:
    length = d.pkw
    if length is None:  # not asked: only drives with a PKW length are refused
        return ""
    conflict = length.conflict
    told = "?" if isinstance(conflict, str) else shown(conflict)
    return (
        f"the drive answers with a PKW length of {told}, the configuration says"
        f" {shown(length.configured)}: no change until they agree (pkw_words)"
    )


def _transaction(
    d: DrivePlan, request: pkw.PkwRequest, job: Job, *, retries: int, stale: bytes | None
) -> PkwTransaction:
    """A transaction of ``job`` (its deadline) for ``request``."""
    return PkwTransaction(d.target, request, retries=retries, deadline=job.deadline, stale=stale)


def gate_write(
    d: DrivePlan, job: Job, order: float, *, retries: int, read_first: bool
) -> Active | Finished:
    """The job in flight, with the read before its change where one goes first; or the
    job finished unsent."""
    request = job.request
    gate = _gate(d, request)
    if gate is Gate.REFUSE:
        return Finished(d.name, job, NotSent(_refusal(d)))
    changes = request.is_write or bool(request.text)
    first = changes and (read_first or gate is Gate.LEARN)
    if first:
        request = pkw.read_parameter(
            d.target.dialect, request.pnu, request.subindex or None, text=bool(request.text)
        )
    tx = _transaction(d, request, job, retries=retries, stale=None)
    return Active(tx, job.priority, order, job, Send(d.name, d.target, tx.telegram), first)


def after_read(
    d: DrivePlan, active: Active, job: Job, outcome: Outcome, *, retries: int
) -> Active | Finished:
    """After the read before a change: the change in flight (the read's answer its stale
    one), or the job finished unsent (never as if the change had gone out: no tally)."""
    if isinstance(outcome, Cancelled | TimedOut | LineFailed):
        return Finished(d.name, job, outcome)  # no answer to go by
    gate = _gate(d, job.request)
    if gate is Gate.REFUSE:
        return Finished(d.name, job, NotSent(_refusal(d)))
    if gate is not Gate.SEND:
        reason = (
            "the drive's answer to a read of the parameter fits both 4 fixed PKW words and"
            " a variable length (a double word, or a text of 4 characters), and where a word"
            " or a text goes depends on it: set pkw_words for this drive"
        )
        return Finished(d.name, job, NotSent(reason))
    tx = _transaction(d, job.request, job, retries=retries, stale=d.last_answer)
    return Active(tx, active.priority, active.order, job, Send(d.name, d.target, tx.telegram))
