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

Where the drive's carrier says it never repeats an answer (a PROFIBUS PKW slot
waits for AK 0 before each job; a data record 47 response answers its own
request reference), the change goes out at once.
"""

from __future__ import annotations

from pkwbus.master.planning.carrier import Item
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
from pkwbus.master.planning.plan import Finished
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.protocol.pkw.length import Gate

__all__ = ["after_read", "gate_write"]


_ARRAY_CHANGES = frozenset(
    {
        Command.WRITE_ARRAY_WORD,
        Command.WRITE_ARRAY_DWORD,
        Command.WRITE_ARRAY_WORD_EEPROM,
        Command.WRITE_ARRAY_DWORD_EEPROM,
    }
)


def _read_of(d: DrivePlan, request: pkw.PkwRequest) -> pkw.PkwRequest:
    """The read of the parameter (the element) a change is for."""
    index = request.subindex if request.command in _ARRAY_CHANGES else None
    return pkw.read_parameter(d.carrier.dialect, request.pnu, index, text=bool(request.text))


def _active(
    d: DrivePlan, request: pkw.PkwRequest, job: Job, order: float, first: bool, *, retries: int,
    stale: bytes | None,
) -> Active | Finished:  # fmt: skip
    """``request`` of ``job`` in flight; a request the drive's PKW block cannot carry ends
    the job unsent (its length learned meanwhile, say)."""
    item = Item(request, job.fmt.vtype)
    try:
        tx = d.transaction([item], retries=retries, deadline=job.deadline, stale=stale)
    except LocalProtocolError as exc:
        return Finished(d.name, job, NotSent(str(exc)))
    return Active(tx, job.priority, order, job, d.send_of(tx), first)


def gate_write(d: DrivePlan, job: Job, order: float, *, retries: int) -> Active | Finished:
    """The job in flight, with the read before its change where one goes first; or the
    job finished unsent."""
    request = job.request
    gate, why = d.carrier.gate(request)
    if gate is Gate.REFUSE:
        return Finished(d.name, job, NotSent(why))
    changes = request.is_write or bool(request.text)
    first = changes and (d.carrier.repeats_answers or gate is Gate.LEARN)
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
    gate, why = d.carrier.gate(job.request)
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
