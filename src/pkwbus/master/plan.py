"""What the planner is given and what it gives: drives and polls in; actions and events out.

Actions are a closed union (:data:`Action`): send one telegram now, or stay
idle until a time. Events (:data:`Event`) tell what the plan came to: a job
or poll finished, a poll started late, a drive's health changed, a status
word arrived. All are small frozen values: the planner does no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.jobs import Job
from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import Outcome, Tally
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw_length import PkwLength

__all__ = [
    "Action",
    "DriveSpec",
    "Event",
    "Finished",
    "HealthChanged",
    "Idle",
    "Overrun",
    "PkwLengthTold",
    "PollSpec",
    "Send",
    "StatusWord",
]


@dataclass(frozen=True)
class PollSpec:
    """One parameter a drive is polled for, every ``every`` seconds."""

    parameter: str  # as configured: the metric label
    index: int
    request: pkw.PkwRequest
    every: float
    fmt: ParameterDescription = field(default_factory=ParameterDescription)


@dataclass(frozen=True)
class DriveSpec:
    name: str
    target: DriveTarget
    polls: tuple[PollSpec, ...] = ()


# ------------------------------------------------------------------ actions


@dataclass(frozen=True, slots=True)
class Send:
    """Exchange ``telegram`` with ``drive`` now; give the result to ``Planner.exchanged``."""

    drive: str
    target: DriveTarget
    telegram: bytes
    probe: bool = False  # the drive is down: one short telegram to see whether it answers


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
    work: Job | PollSpec
    outcome: Outcome
    tally: Tally | None = None


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


Event = Finished | Overrun | HealthChanged | StatusWord | PkwLengthTold
