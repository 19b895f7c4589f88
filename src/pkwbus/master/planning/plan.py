"""What the planner is given and what it gives: drives and polls in; actions and events out.

Actions are a closed union (:data:`Action`): send one telegram now, or stay
idle until a time. Events (:data:`Event`) tell what the plan came to: a job
or poll finished, a poll started late, a drive's health changed, a status
word arrived. All are small frozen values: the planner does no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

from pkwbus.catalog.alarms import AlarmDecoder
from pkwbus.catalog.description import ParameterDescription
from pkwbus.catalog.precedence import Layers
from pkwbus.master.planning.carrier import Carrier, Item
from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.master.planning.jobs import Job, ProbeJob
from pkwbus.master.planning.outcomes import Outcome
from pkwbus.master.planning.transaction import Tally
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import DescriptionForm, DriveDescription
from pkwbus.protocol.pkw.length import PkwLength

__all__ = [
    "Action",
    "DescribeTarget",
    "Described",
    "DescribedAnew",
    "DescribedFromBook",
    "DescriptionSettled",
    "DriveSpec",
    "Event",
    "Finished",
    "Forgotten",
    "HealthChanged",
    "Idle",
    "LeftUnanswered",
    "Overrun",
    "PkwLengthTold",
    "PollBatch",
    "PollSpec",
    "PollState",
    "Redecoded",
    "Send",
    "StatusWord",
    "polls_of",
]


@dataclass(frozen=True)
class PollSpec:
    """One parameter a drive is polled for, every ``every`` seconds."""

    parameter: str  # as configured: the metric label
    index: int
    request: pkw.PkwRequest
    every: float
    fmt: ParameterDescription = field(default_factory=ParameterDescription)
    # What the configuration and the catalog say of it, for the drive's description to
    # be put in between (None: the drive is not asked to describe it).
    layers: Layers | None = None
    # Its type is known only from the drive's description (no vendor document types it):
    # it waits until the drive describes a type, and without one it is not polled.
    described_only: bool = False

    @cached_property
    def items(self) -> tuple[Item]:
        """Its request as the one item of a transaction, made once."""
        return (Item(self.request),)


class PollState:
    """A poll and when it is due."""

    __slots__ = ("due", "fresh", "retired", "spec")

    def __init__(self, spec: PollSpec, due: float) -> None:
        self.spec = spec
        self.due = due
        # Waited for its parameter's description: its first start is never an overrun.
        self.fresh = False
        self.retired = False  # no longer configured (a reload): never due again


@dataclass(frozen=True, slots=True)
class PollBatch:
    """Polls due together in one request, where the drive's carrier takes many parameters
    in one (PROFIdrive data record 47): each ends with its own outcome."""

    polls: tuple[PollState, ...]

    def __len__(self) -> int:
        return len(self.polls)


def polls_of(work: object) -> tuple[PollState, ...]:
    """The polls a transaction's work carries: a poll, a batch's, or none."""
    if isinstance(work, PollBatch):
        return work.polls
    return (work,) if isinstance(work, PollState) else ()


@dataclass(frozen=True)
class DescribeTarget:
    """A parameter the drive is asked to describe before its first value (AK 4)."""

    pnu: int
    parameter: str  # the drive's name for it: the metric label
    elements: tuple[int, ...]
    catalog: ParameterDescription | None = None  # its catalog entry, to cross-check
    writable: bool = False  # the configuration lists it as writable


@dataclass(frozen=True)
class DriveSpec:
    """A drive on a line: its name, how its jobs travel, its polls and what it describes."""

    name: str
    carrier: Carrier
    polls: tuple[PollSpec, ...] = ()
    describe: tuple[DescribeTarget, ...] = ()
    form: DescriptionForm | None = None  # how the drive describes (None: it is not asked)
    # Descriptions by drive identity, shared by every drive (None: none are kept).
    book: DescriptionBook | None = None
    # The polled parameters (name, index) whose values tell active alarms, with their
    # decoders: what the snapshot's writer keeps of them; the planner does not read it.
    alarms: tuple[tuple[str, int, AlarmDecoder], ...] = ()


# ------------------------------------------------------------------ actions


@dataclass(frozen=True, slots=True)
class Send:
    """Exchange ``telegram`` with ``drive`` (its answers come from ``address``) now; give the
    result to ``Planner.exchanged``. Empty ``telegram``: its carrier's wire builds what goes
    out (a PPO's PKW slot, a data record transfer)."""

    drive: str
    address: int
    telegram: bytes
    probe: bool = False  # the drive is down: one short telegram to see whether it answers
    words: int | None = None  # a probe's PKW words, where its carrier keeps them apart


@dataclass(frozen=True, slots=True)
class Idle:
    """Nothing to send before ``until`` (loop time), unless a job comes in."""

    until: float


Action = Send | Idle


# ------------------------------------------------------------------- events


@dataclass(frozen=True, slots=True)
class Finished:
    """A job or a poll is over. ``tally``: what its exchanges cost (None when none went out)."""

    drive: str
    work: Job | ProbeJob | PollSpec
    outcome: Outcome
    tally: Tally | None = None
    gone: bool = False  # its drive left the line (a reload): for the job's caller alone


@dataclass(frozen=True, slots=True)
class Overrun:
    """A poll started later than one interval after it was due."""

    drive: str


@dataclass(frozen=True, slots=True)
class HealthChanged:
    """The drive is shown up or down. ``reason`` is empty when only its line changed."""

    drive: str
    up: bool
    reason: str = ""


@dataclass(frozen=True, slots=True)
class StatusWord:
    """A reply's status word, and its main actual value when it has a second PZD word."""

    drive: str
    word: int
    main_actual: int | None = None


@dataclass(frozen=True, slots=True)
class PkwLengthTold:
    """What a USS drive's answers told of its PKW length changed: learned (``auto``),
    learned again, or in conflict with the configured length (or agreeing again)."""

    drive: str
    length: PkwLength  # a copy, as it was then


@dataclass(frozen=True, slots=True)
class _Settled:
    """A parameter's description settled: what the drive said (None: nothing, ``why``), its
    polls as they go out from now on, and its catalog entry (``target``, to cross-check);
    ``first``: the first time it settled (what is logged once); ``identity``: the drive's
    model and software, when known; ``withheld``: polls that wait for a type the drive did
    not describe (``PollSpec.described_only``)."""

    drive: str
    target: DescribeTarget
    description: DriveDescription | None
    polls: tuple[PollSpec, ...]
    why: str = ""
    first: bool = True
    identity: str | None = None
    withheld: tuple[PollSpec, ...] = ()


@dataclass(frozen=True, slots=True)
class DescribedAnew(_Settled):
    """Settled by the drive's answers now (or by its saying nothing of it: ``why``)."""


@dataclass(frozen=True, slots=True)
class DescribedFromBook(_Settled):
    """Settled from the book: known from a drive of the same identity, or an earlier run."""


@dataclass(frozen=True, slots=True)
class LeftUnanswered(_Settled):
    """The drive left it unanswered: the catalog stands (``description`` None), and it is
    asked again later."""


@dataclass(frozen=True, slots=True)
class Forgotten:
    """The drive is another one now (its identity changed), or it came back after it was
    away: the parameter is described afresh, its values waiting for it."""

    drive: str
    target: DescribeTarget
    why: str
    identity: str | None = None


@dataclass(frozen=True, slots=True)
class Redecoded:
    """New polls of a parameter described before (a reload): their decoding, told again."""

    drive: str
    target: DescribeTarget
    description: DriveDescription | None
    polls: tuple[PollSpec, ...]
    identity: str | None = None


DescriptionSettled = DescribedAnew | DescribedFromBook | LeftUnanswered
# What became of a parameter's description: one of these states, never a set of flags.
Described = DescribedAnew | DescribedFromBook | LeftUnanswered | Forgotten | Redecoded

Event = Finished | Overrun | HealthChanged | StatusWord | PkwLengthTold | Described
