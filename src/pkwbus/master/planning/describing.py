"""Reading a drive's description of its parameters (AK 4) before their first value.

One :class:`DriveDescriber` per drive whose dialect has description elements.
It gives the planner one element request at a time (:meth:`next_request`),
parameter by parameter, and folds each answer in (:meth:`took`). A parameter
is *settled* when every element it needs was answered or refused, when the
drive refuses its first element (it has no description: the rest is not
asked), or when the drive left :data:`UNANSWERED_AT_MOST` description
requests in a row unanswered (each after its retries; a down drive is not
asked): then the catalog stands for every parameter still waiting, with one
log line each, and they are asked again :data:`ASK_AGAIN` seconds later.
A parameter's polls wait until it settles, so that no value goes out with a
scaling about to change.

Pure: time passed in, no I/O.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Final

from pkwbus.catalog.precedence import resolve
from pkwbus.master.planning.identity import DescriptionBook, identity_of
from pkwbus.master.planning.outcomes import Answered, Cancelled, LineFailed, Outcome, Rejected
from pkwbus.master.planning.plan import PollSpec
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import (
    DATA_TYPE,
    LIMITS,
    DescriptionForm,
    DriveDescription,
    read_elements,
)
from pkwbus.protocol.pkw.dialects import Command, Dialect

__all__ = [
    "ASK_AGAIN",
    "CLAIM_RECHECK",
    "UNANSWERED_AT_MOST",
    "DescribeStep",
    "DriveDescriber",
    "Settled",
    "described_poll",
]

ASK_AGAIN: Final = 600.0  # seconds until a drive that did not describe is asked again
UNANSWERED_AT_MOST: Final = 2  # requests of one parameter left unanswered before the catalog
CLAIM_RECHECK: Final = 0.2  # s: a drive waiting for another of its kind to describe looks again


@dataclass(frozen=True, slots=True)
class DescribeStep:
    """One element request of one parameter, or one read of the drive's identity
    (``identity``): what an :class:`~.drive_plan.Active` carries."""

    pnu: int
    element: int
    request: pkw.PkwRequest
    identity: bool = False
    round: int = 0  # of the identity reads: an answer of an earlier round is not this one's


@dataclass(frozen=True, slots=True)
class Settled:
    """A parameter's description is known, or known not to come.

    ``description`` is None when the drive gave none (``why`` says why: it
    refuses, or did not answer in time).
    """

    pnu: int
    description: DriveDescription | None
    why: str = ""
    first: bool = True  # its first settling (its polls were waiting for it)
    identity: str | None = None  # the drive's model and software, when known
    from_book: bool = False  # known from another drive of that identity, or an earlier run
    unanswered: bool = False  # left unanswered: the catalog stands, asked again later


@dataclass
class _Parameter:
    pnu: int
    elements: tuple[int, ...]
    found: dict[int, pkw.DescriptionResponse | None] = field(default_factory=dict)
    due: float = 0.0  # when it may be asked (again)
    settled: bool = False
    unanswered: bool = False  # settled for want of answers: the catalog stands for now
    # What another drive of its kind described of it (the book): only its limits are read.
    base: DriveDescription | None = None

    def next_element(self) -> int | None:
        return next((e for e in self.elements if e not in self.found), None)


class DriveDescriber:
    """What is still to be described of one drive's parameters, and what was."""

    def __init__(
        self,
        dialect: Dialect,
        form: DescriptionForm,
        wanted: Iterable[tuple[int, tuple[int, ...]]],  # (PNU, elements to read)
        *,
        book: DescriptionBook | None = None,
        identity: Sequence[pkw.PkwRequest] = (),  # the reads that identify the drive
    ) -> None:
        self.dialect = dialect
        self.form = form
        self._params = {pnu: _Parameter(pnu, elements) for pnu, elements in wanted}
        self.described: dict[int, DriveDescription | None] = {}
        self.unanswered = 0  # description requests in a row that ended without an answer
        self.book = book
        self._identify = tuple(identity) if book is not None else ()
        self._answers: list[Outcome] = []
        self._identify_due: float | None = 0.0 if self._identify else None
        self._round = 0
        self.identity: str | None = None
        self.changed = False  # the drive's identity changed: every parameter waits again
        self.ready: list[Settled] = []  # settled from the book, for the planner to tell
        self._blocked: float | None = None  # all it could ask, another drive is asking

    def want(self, pnu: int, elements: tuple[int, ...]) -> None:
        """Describe ``pnu`` by ``elements`` from now on (a reload): a new parameter waits
        for its description; one described already keeps it until the elements it lacked
        (its limits, say) are read."""
        param = self._params.get(pnu)
        if param is None:
            self._params[pnu] = _Parameter(pnu, elements)
        elif param.elements != elements:
            param.elements = elements
            if param.next_element() is not None:  # read afresh, its description standing
                param.settled, param.found, param.due, param.base = False, {}, 0.0, None

    def release(self) -> None:
        """The drive is away: another drive of its kind describes what it was describing."""
        if self.book is not None:
            self.book.release(self)

    def recheck(self) -> list[int]:
        """The drive answers again after it was away: it may have been replaced, and what
        it left unanswered (it was away) waits for its description again, so that no value
        goes out with a description it may not have. The PNUs waiting again."""
        if self._identify:
            self.release()
            self._answers, self._identify_due = [], 0.0
            self._round += 1
        again = []
        for param in self._params.values():
            if param.unanswered and self.described.get(param.pnu, 0) is None:
                del self.described[param.pnu]
                param.settled, param.found, param.due, param.unanswered = False, {}, 0.0, False
                param.base = None
                again.append(param.pnu)
        return again

    def reask(self, pnus: Iterable[int]) -> list[int]:
        """Ask again for the descriptions of ``pnus`` the drive refused (a refusal may be
        its state, not its kind): polls that wait for a type it did not give. The PNUs
        waiting again."""
        again = []
        for pnu in pnus:
            param = self._params.get(pnu)
            if param is None or not param.settled or self.described.get(pnu, 0) is not None:
                continue
            del self.described[pnu]
            param.settled, param.found, param.due, param.unanswered = False, {}, 0.0, False
            param.base = None
            again.append(pnu)
        return again

    def waiting(self, pnu: int) -> bool:
        """Whether the polls of ``pnu`` wait for its description."""
        param = self._params.get(pnu)
        return param is not None and not param.settled and pnu not in self.described

    def due(self) -> float | None:
        """When the next element request may go out; None when nothing is left."""
        if self._identify_due is not None:
            return self._identify_due
        dues = [p.due for p in self._params.values() if not p.settled]
        if not dues:
            return None
        if self._blocked is not None:
            return max(min(dues), self._blocked)
        return min(dues)

    def next_request(self, now: float) -> DescribeStep | None:
        """The next element to ask, of the parameter due first; None when none is due."""
        if self._identify_due is not None:
            if self._identify_due > now:
                return None
            request = self._identify[len(self._answers)]
            return DescribeStep(request.pnu, request.subindex, request, True, self._round)
        self._blocked = None
        book, identity = self.book, self.identity
        for param in sorted(
            (p for p in self._params.values() if not p.settled and p.due <= now),
            key=lambda p: p.due,
        ):
            if book is not None and identity is not None and param.base is None:
                found = book.get(identity, param.pnu, _shared(param.elements))
                if found is not None and _shared(param.elements) == param.elements:
                    self.ready.append(self._settle(param, found, "", now, from_book=True))
                    continue
                if found is not None:  # its kind is known: its own limits are read alone
                    param.base = found
                    param.found = {
                        e: _type_element(param.pnu, found) if e == DATA_TYPE else None
                        for e in _shared(param.elements)
                    }
                elif not book.claim(identity, param.pnu, self):
                    continue  # another drive of its kind is asking: its answer will do
            element = param.next_element()
            assert element is not None  # a parameter with all its elements has settled
            request = pkw.read_description(self.dialect, param.pnu, element)
            return DescribeStep(param.pnu, element, request)
        if any(not p.settled and p.due <= now for p in self._params.values()):
            self._blocked = now + CLAIM_RECHECK
        return None

    def take_ready(self) -> list[Settled]:
        ready, self.ready = self.ready, []
        return ready

    def took(self, step: DescribeStep, outcome: Outcome, now: float) -> list[Settled]:
        """Fold in what came of ``step``; the parameters that settled by it."""
        if step.identity:
            if step.round != self._round or self._identify_due is None:
                return []  # asked before the drive was away: not this round's answer
            self._answers.append(outcome)
            return self._identified(now) if len(self._answers) == len(self._identify) else []
        param = self._params[step.pnu]
        if param.settled:
            return []
        response = outcome.response if isinstance(outcome, Answered) else None
        if isinstance(response, pkw.DescriptionResponse):
            param.found[step.element] = response
        elif isinstance(outcome, Rejected | Answered):  # refused, or no description in it
            if step.element == DATA_TYPE and not param.found:
                why = f"the drive has no description of it ({_said(outcome)})"
                return [self._settle(param, None, why, now)]
            param.found[step.element] = None
        elif isinstance(outcome, LineFailed | Cancelled):
            return []  # the line went away, or the service stops: not the drive's silence
        else:  # no answer within the request's retries
            self.unanswered += 1
            if self.unanswered >= UNANSWERED_AT_MOST:
                why = f"no answer to {self.unanswered} description requests in a row"
                self.unanswered = 0
                return [
                    self._settle(p, None, why, now, retry=True)
                    for p in self._params.values()
                    if p is param or self.waiting(p.pnu)
                ]
            return []
        self.unanswered = 0
        if param.next_element() is None:
            found = read_elements(self.form, param.found)
            if param.base is not None:  # the kind's description, with this drive's limits
                found = replace(param.base, low_raw=found.low_raw, high_raw=found.high_raw)
            return [self._settle(param, None if found.empty else found, "", now)]
        return []

    def _identified(self, now: float) -> list[Settled]:
        """The identity is read: a drive replaced by another is described afresh; what the
        book knows of this identity settles at once."""
        identity = identity_of(self.dialect, self._answers)
        previous = self.identity
        self._answers, self._identify_due = [], None
        if identity is None:  # not told this time: the drive is still the one it was
            return []
        self.identity = identity
        if previous is not None and identity != previous:
            self.again()
            self.described.clear()
            self.changed = True
        book = self.book
        if identity is None or book is None:
            return []
        settled = []
        for param in self._params.values():
            found = book.get(identity, param.pnu, param.elements)
            if found is not None and self.waiting(param.pnu):
                settled.append(self._settle(param, found, "", now, from_book=True))
        return settled

    def again(self, pnus: Iterable[int] | None = None) -> None:
        """Describe ``pnus`` (all when None) afresh: the drive may have changed."""
        self.release()
        for param in self._params.values():
            if pnus is None or param.pnu in pnus:
                param.found.clear()
                param.base = None
                param.settled, param.due = False, 0.0

    def _settle(
        self,
        param: _Parameter,
        found: DriveDescription | None,
        why: str,
        now: float,
        *,
        retry: bool = False,
        from_book: bool = False,
    ) -> Settled:
        first = param.pnu not in self.described
        param.settled = True
        if self.book is not None:
            self.book.release(self, param.pnu)
        param.unanswered = retry
        if retry:  # not answered in time: the catalog stands; the drive is asked again later
            param.settled, param.found, param.due = False, {}, now + ASK_AGAIN
            param.base = None
        elif self.identity and self.book is not None and found is not None and not from_book:
            # A refusal is not kept: it may be the drive's state, not its kind. Nor are the
            # limits: a drive's may follow its other settings (FC 4-14 follows 4-19), so a
            # writable parameter is described by each start afresh.
            kept = replace(found, low_raw=None, high_raw=None)
            read = [e for e in param.elements if e not in LIMITS]
            self.book.put(self.identity, param.pnu, kept, read)
        if found is not None or first:
            self.described[param.pnu] = found
        return Settled(param.pnu, found, why, first, self.identity, from_book, retry)


def _shared(elements: tuple[int, ...]) -> tuple[int, ...]:
    """The elements drives of one kind share: all but the limits."""
    return tuple(e for e in elements if e not in LIMITS)


def _type_element(pnu: int, kind: DriveDescription) -> pkw.DescriptionResponse | None:
    """Element 1 as the book knows it, to read this drive's limits by (the type code is
    the low byte in both forms)."""
    if kind.type_code is None:
        return None
    return pkw.DescriptionResponse(0, pnu, DATA_TYPE, kind.type_code, b"", pkw.Width.WORD)


def _said(outcome: Outcome) -> str:
    if isinstance(outcome, Rejected):
        return outcome.text or outcome.short or f"fault {outcome.fault}"
    return "no description element in its answer"


def described_poll(spec: PollSpec, settled: Settled, dialect: Dialect) -> PollSpec:
    """``spec`` decoded (and read: text or value) as its parameter is now described."""
    if spec.layers is None:
        return spec
    fmt = resolve(spec.layers, settled.description).description
    request = spec.request
    if fmt.is_text != spec.fmt.is_text:
        indexed = request.subindex or request.command is Command.READ_ARRAY
        index = request.subindex if indexed else None
        request = pkw.read_parameter(dialect, request.pnu, index, text=fmt.is_text)
    return replace(spec, fmt=fmt, request=request)
