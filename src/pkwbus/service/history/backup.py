"""A drive's settings as a document a person can read and keep, and the plan of restoring
it to a drive (the same one, or its replacement).

The backup document (JSON or YAML): the drive's identity (its model and software as read
from it), its dialect and catalog, the Danfoss active set-up where the drive answered
0-10, when it was made, and every swept setting with its value, unit and raw number, in
the order the sweep reads them.

A restore plans the writes of what differs from the target's present values, in the
backup's order, and skips, each with its reason, what cannot be written: a read-only
parameter (the catalog's ``r``, the drive's description, FC element 21's "can only be
read over the bus"), one with no bus access (FC element 21, bit 9), a value outside the
target's limits, a parameter the target refuses to read, a backup of another drive type
(unless forced). Pure: the reads and writes are the caller's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictFloat, StrictInt, StrictStr

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.protocol.pkw.descriptions import Characteristics

__all__ = [
    "FORMAT",
    "Backup",
    "BackupSetting",
    "Planned",
    "Present",
    "Skipped",
    "drive_type",
    "plan_restore",
]

FORMAT: Literal[1] = 1  # of the backup document


class BackupSetting(BaseModel):
    """One setting of a backup: its value as shown (``raw`` the number the drive held)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    parameter: StrictStr = Field(min_length=1, max_length=32)
    index: StrictInt = Field(default=0, ge=0, le=255)
    name: StrictStr = ""
    value: StrictInt | Annotated[StrictFloat, Field(allow_inf_nan=False)] | StrictStr | None = None
    unit: StrictStr = ""
    raw: StrictInt | None = None
    seen: StrictStr | None = None


class Backup(BaseModel):
    """A backup document of one drive's settings."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    pkwbus_backup: Literal[1] = FORMAT
    drive: StrictStr = Field(min_length=1, max_length=64)
    line: StrictStr = ""
    dialect: StrictStr = ""
    catalog: StrictStr | None = None
    identity: StrictStr | None = None
    setup: StrictInt | None = None  # Danfoss 0-10 Active Set-up, as the drive answered it
    time: StrictStr = ""
    settings: list[BackupSetting] = Field(default_factory=list, max_length=4096)


def drive_type(identity: str | None) -> str | None:
    """The model part of a drive's identity (Danfoss FC: 15-40 FC Type; Siemens: r0964
    company and device type), without its software version."""
    if identity is None or ":" not in identity:
        return None
    dialect, _, parts = identity.partition(":")
    found = parts.split("|")
    return f"{dialect}:" + "|".join(found[:1] if dialect == "fc" else found[:2])


@dataclass(frozen=True, slots=True)
class Present:
    """What the target drive says of one setting now: its value (None: it did not answer
    the read, ``refused`` its reason when it refused it), how it describes the parameter,
    and FC element 21 where read."""

    value: Value | None
    fmt: ParameterDescription
    refused: str | None = None
    characteristics: Characteristics | None = None
    read_only: bool = False  # the catalog or the drive says so


@dataclass(frozen=True, slots=True)
class Planned:
    parameter: str
    index: int
    old: Value | None
    new: Value

    def as_dict(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "index": self.index, "from": self.old, "to": self.new}


@dataclass(frozen=True, slots=True)
class Skipped:
    parameter: str
    index: int
    why: str

    def as_dict(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "index": self.index, "why": self.why}


def plan_restore(
    backup: Backup,
    present: Mapping[tuple[str, int], Present],
    *,
    target_identity: str | None,
    force: bool = False,
    target_dialect: str | None = None,
    target_catalog: str | None = None,
) -> tuple[list[Planned], list[Skipped]]:
    """The writes that make the target hold ``backup``'s values, in its order, and what is
    skipped with why. ``present``: the target's answers, by (parameter, index) as the
    backup names them."""
    plan: list[Planned] = []
    skipped: list[Skipped] = []
    other = _other_kind(backup, target_identity, target_dialect, target_catalog)
    if other is not None and not force:
        whole = f"the backup is of {other}: force it"
        return [], [Skipped(s.parameter, s.index, whole) for s in backup.settings]
    for s in backup.settings:
        why = _unwritable(s, present.get((s.parameter, s.index)))
        if why is not None:
            skipped.append(Skipped(s.parameter, s.index, why))
            continue
        now = present[(s.parameter, s.index)]
        assert s.value is not None
        if not _same(now.value, s.value):
            plan.append(Planned(s.parameter, s.index, now.value, s.value))
    return plan, skipped


def _other_kind(
    backup: Backup, identity: str | None, dialect: str | None, catalog: str | None
) -> str | None:
    """What tells the backup is of another kind of drive than the target: its model (where
    both are identified), else its catalog (where both name one; a parameter's number
    means another parameter in another catalog), else its dialect; None: the same kind as
    far as can be told."""
    theirs, ours = drive_type(backup.identity), drive_type(identity)
    if theirs is not None and ours is not None:
        return None if theirs == ours else f"another drive type ({theirs}, this drive is {ours})"
    if backup.catalog and catalog:
        if backup.catalog == catalog:
            return None
        return f"another catalog ({backup.catalog}, this drive's is {catalog})"
    if backup.dialect and dialect and backup.dialect != dialect:
        return f"another dialect ({backup.dialect}, this drive speaks {dialect})"
    return None


def _unwritable(s: BackupSetting, now: Present | None) -> str | None:
    if s.value is None:
        return "the backup has no value of it"
    if isinstance(s.value, str):
        return "a text: not restored"
    if now is None:
        return "not asked"
    readout = _readout(now.fmt)
    if readout is not None:
        return readout
    if now.refused is not None:
        return f"this drive refuses to read it: {now.refused}"
    if now.value is None:
        return "this drive did not answer its read"
    c = now.characteristics
    if c is not None and c.no_bus_access:
        return "no bus access (the drive's additional characteristics, bit 9)"
    if now.read_only or (c is not None and c.bus_read_only):
        return "read-only"
    fmt = now.fmt
    low, high = fmt.minimum, fmt.maximum
    if isinstance(s.value, int | float) and (
        (low is not None and s.value < low) or (high is not None and s.value > high)
    ):
        return f"{s.value} is outside this drive's limits {_limits(low, high, fmt.unit)}"
    return None


def _readout(fmt: ParameterDescription) -> str | None:
    """Why a parameter the catalog knows as a readout is never written by a restore,
    whatever the drive describes of it: a counter the drive keeps of its own life
    (operating hours, energy), or a display parameter (``r``)."""
    if fmt.counter:
        return "a readout: a counter the drive keeps itself, never restored"
    if fmt.prefix == "r":
        return "a readout (an r parameter), never restored"
    return None


def _same(a: Value | None, b: Value) -> bool:
    if isinstance(a, int | float) and isinstance(b, int | float):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    return a == b


def _limits(low: float | None, high: float | None, unit: str) -> str:
    lowest = "-inf" if low is None else f"{low:g}"
    highest = "inf" if high is None else f"{high:g}"
    return f"{lowest}..{highest} {unit}".strip()
