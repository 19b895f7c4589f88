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
  is learned (``pkw_words: auto``; :mod:`pkwbus.protocol.pkw.length`), and
  nothing is changed on a drive whose answers contradict the configured
  length, until the two agree.

A PROFIBUS PKW slot waits for AK 0 before each job instead (no stale answer
can be taken), so there the change goes out at once; so does a change in data
record 47, whose response answers its own request reference.
"""

from __future__ import annotations

from pkwbus.master.planning.drive import Active, DrivePlan
from pkwbus.master.planning.jobs import Job
from pkwbus.master.planning.outcomes import (
    Cancelled,
    LineFailed,
    NotSent,
    Outcome,
    Rejected,
    TimedOut,
)
from pkwbus.master.planning.plan import Finished, Send
from pkwbus.master.planning.record_transaction import RecordItem
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.protocol.pkw.fields import Width
from pkwbus.protocol.pkw.length import Gate, shown

__all__ = ["after_read", "gate_write"]


_ARRAY_CHANGES = frozenset(
    {
        Command.WRITE_ARRAY_WORD,
        Command.WRITE_ARRAY_DWORD,
        Command.WRITE_ARRAY_WORD_EEPROM,
        Command.WRITE_ARRAY_DWORD_EEPROM,
    }
)


def _gate(d: DrivePlan, request: pkw.PkwRequest) -> tuple[Gate, str]:
    """Whether ``request`` may go out to ``d`` now; why not, in words, when refused."""
    length = d.pkw
    if length is None or (not request.is_write and not request.text):
        return Gate.SEND, ""
    word = request.width is Width.WORD and not request.text
    gate, why = length.gate(word=word, text=bool(request.text))
    if gate is Gate.REFUSE and length.in_conflict:
        conflict = length.conflict
        told = "?" if isinstance(conflict, str) else shown(conflict)
        why = (
            f"the drive answers with a PKW length of {told}, the configuration says"
            f" {shown(length.configured)}: no change until they agree (pkw_words)"
        )
    return gate, why


def _read_of(d: DrivePlan, request: pkw.PkwRequest) -> pkw.PkwRequest:
    """The read of the parameter (the element) a change is for."""
    index = request.subindex if request.command in _ARRAY_CHANGES else None
    return pkw.read_parameter(d.target.dialect, request.pnu, index, text=bool(request.text))


def _active(
    d: DrivePlan, request: pkw.PkwRequest, job: Job, order: float, first: bool, *, retries: int,
    stale: bytes | None,
) -> Active | Finished:  # fmt: skip
    """``request`` of ``job`` in flight; a request the drive's PKW block cannot carry ends
    the job unsent (its length learned meanwhile, say)."""
    item = RecordItem(request, job.fmt.vtype)
    try:
        tx = d.transaction([item], retries=retries, deadline=job.deadline, stale=stale)
    except LocalProtocolError as exc:
        return Finished(d.name, job, NotSent(str(exc)))
    return Active(tx, job.priority, order, job, Send(d.name, d.target, tx.telegram), first)


def gate_write(
    d: DrivePlan, job: Job, order: float, *, retries: int, read_first: bool
) -> Active | Finished:
    """The job in flight, with the read before its change where one goes first; or the
    job finished unsent."""
    request = job.request
    gate, why = _gate(d, request)
    if gate is Gate.REFUSE:
        return Finished(d.name, job, NotSent(why))
    changes = request.is_write or bool(request.text)
    read_first = read_first and d.target.record is None  # a record answers its own request
    first = changes and (read_first or gate is Gate.LEARN)
    if first:
        request = _read_of(d, request)
    return _active(d, request, job, order, first, retries=retries, stale=None)


def after_read(
    d: DrivePlan, active: Active, job: Job, outcome: Outcome, *, retries: int
) -> Active | Finished:
    """After the read before a change: the change in flight (the read's answer its stale
    one), or the job finished unsent (never as if the change had gone out: no tally)."""
    if isinstance(outcome, Cancelled | TimedOut | LineFailed):
        return Finished(d.name, job, outcome)  # no answer to go by
    if isinstance(outcome, Rejected):
        # The drive refuses the parameter (no such PNU, index or access): its change is not
        # sent, the refusal is the job's answer. (Sent anyway, its own refusal would read
        # as the read's repeated, and the change would go out again until its deadline.)
        return Finished(d.name, job, outcome)
    gate, why = _gate(d, job.request)
    if gate is Gate.LEARN:
        why = (
            "the drive's answer to a read of the parameter fits both 4 fixed PKW words and"
            " a variable length (a double word, or a text of 4 characters), and where a word"
            " or a text goes depends on it: set pkw_words for this drive"
        )
    if gate is not Gate.SEND:
        return Finished(d.name, job, NotSent(why))
    order = active.order
    return _active(d, job.request, job, order, False, retries=retries, stale=d.last_answer)
