"""The reads of a drive's settings sweep, by background jobs of its line: each setting's
value, and what the drive says of its factory setting (FC description elements 20 and 21,
read once per run; PROFIdrive identifier bit 12, read with each value), as
:mod:`pkwbus.protocol.pkw.descriptions` reads them."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.errors import PkwbusError
from pkwbus.master.planning.jobs import Job, JobKind, JobResult, Priority
from pkwbus.master.planning.outcomes import Answered, Rejected
from pkwbus.master.snapshot import Snapshot
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import (
    CHARACTERISTICS,
    DATA_TYPE,
    FACTORY,
    Characteristics,
    DescriptionForm,
    changed_from_factory,
    factory_raw,
)
from pkwbus.protocol.values import ParameterRef
from pkwbus.service.history.settings_store import SettingRow
from pkwbus.service.runtime import DriveEntry, LineTask

__all__ = ["SettingReads", "Swept", "Unanswered"]

log = logging.getLogger("pkwbus.service.settings")


@dataclass
class Swept:
    """A drive whose settings are swept: its line, what it reads, what is known of it."""

    line: str
    entry: DriveEntry
    every: float
    refs: Sequence[ParameterRef]
    catalog: str | None = None
    # How the drive describes its parameters, when it is asked to (``describe: auto``).
    form: DescriptionForm | None = None
    offset: float = 0.0  # its first read, after the start: drives on a line take turns
    identity: str | None = None  # the one its baseline belongs to
    told: str | None = None  # the one its line told last
    loaded: bool = False  # what the history keeps of it is loaded
    swept: float | None = None
    completed: int = 0  # complete sweeps in this run
    reads: int = 0  # settings values read in this run
    rows: dict[tuple[int, int], SettingRow] = field(default_factory=dict)
    # What the drive says of each PNU's factory setting (FC elements 20, 21) and, per
    # setting, whether it differs from it (PROFIdrive bit 12); absent: not asked yet.
    factory: dict[int, int | float | None] = field(default_factory=dict)
    characteristics: dict[int, Characteristics | None] = field(default_factory=dict)
    from_factory: dict[int, bool | None] = field(default_factory=dict)
    refused: dict[tuple[int, int], str] = field(default_factory=dict)
    # Writes pkwbus made whose answer was lost (or not yet stored), by setting: the raw
    # number a sweep takes as pkwbus's.
    expected: dict[tuple[int, int], int] = field(default_factory=dict)
    # The read model whose decoding tells what the drive described (None: nothing).
    snapshot: Snapshot | None = None

    @property
    def drive(self) -> str:
        return self.entry.name

    def format_of(self, ref: ParameterRef) -> ParameterDescription:
        """What is known of ``ref`` now, with what the drive described of it."""
        decoding = self.snapshot.decoding.get(self.drive) if self.snapshot else None
        return self.entry.format_of(ref, decoding.described if decoding is not None else {})


class Unanswered(PkwbusError):
    """A read got no answer (timeout, line down, maintenance): read again next sweep."""


class SettingReads:
    """The settings reads of the drives of ``runners``' lines."""

    def __init__(self, runners: dict[str, LineTask], job_timeout: float = 30.0) -> None:
        self.runners = runners
        self.job_timeout = job_timeout

    async def read(self, s: Swept, ref: ParameterRef) -> tuple[int, Value] | None:
        """One setting's raw number and value (and, the first time, what the drive says of
        its factory setting); None when it is not swept (a text, or the drive refuses it).
        :class:`Unanswered` when a read got no answer."""
        key = (ref.pnu, ref.index or 0)
        fmt = s.format_of(ref)
        if fmt.is_text:
            s.refused[key] = "a text: not swept"
            return None
        d = s.entry.target.dialect
        form = s.form
        if form is DescriptionForm.DANFOSS_FC and ref.pnu not in s.factory:
            told = await self._ask(
                s,
                [
                    pkw.read_description(d, ref.pnu, FACTORY),
                    pkw.read_description(d, ref.pnu, CHARACTERISTICS),
                ],
            )
            factory, characteristics = told
            s.factory[ref.pnu] = (
                factory_raw(factory, fmt.vtype)
                if isinstance(factory, pkw.DescriptionResponse) else None
            )  # fmt: skip
            s.characteristics[ref.pnu] = (
                Characteristics.of(characteristics)
                if isinstance(characteristics, pkw.DescriptionResponse) else None
            )  # fmt: skip
        if form is DescriptionForm.PROFIDRIVE:
            (ident,) = await self._ask(s, [pkw.read_description(d, ref.pnu, DATA_TYPE)])
            s.from_factory[ref.pnu] = (
                changed_from_factory(ident) if isinstance(ident, pkw.DescriptionResponse)
                else None
            )  # fmt: skip
        result = await self._submit(s, pkw.read(d, ref.pnu, ref.index), fmt, ref)
        outcome = result.outcome
        if isinstance(outcome, Rejected):
            if s.refused.get(key) != outcome.text:
                log.warning(
                    "drive %s: setting %s is not swept: the drive refuses it (%s)", s.drive,
                    ref.name, outcome.text, extra={"line": s.line, "drive": s.drive},
                )  # fmt: skip
            s.refused[key] = outcome.text
            return None
        if not isinstance(outcome, Answered) or result.raw is None or result.value is None:
            raise Unanswered()
        s.refused.pop(key, None)
        s.reads += 1
        return result.raw, result.value

    async def _ask(self, s: Swept, requests: list[pkw.PkwRequest]) -> list[pkw.PkwResponse | None]:
        """Description elements: each answer, None where the drive refused it."""
        found: list[pkw.PkwResponse | None] = []
        for request in requests:
            outcome = (await self._submit(s, request, ParameterDescription(), None)).outcome
            if isinstance(outcome, Answered):
                found.append(outcome.response)
            elif isinstance(outcome, Rejected):
                found.append(None)
            else:
                raise Unanswered()
        return found

    async def _submit(
        self,
        s: Swept,
        request: pkw.PkwRequest,
        fmt: ParameterDescription,
        ref: ParameterRef | None,
    ) -> JobResult:
        runner = self.runners.get(s.line)
        if runner is None:
            raise Unanswered()
        loop = asyncio.get_running_loop()
        future: asyncio.Future[JobResult] = loop.create_future()
        deadline = loop.time() + max(self.job_timeout, s.every / max(1, len(s.refs)))
        name, index = (ref.name, ref.index or 0) if ref is not None else ("", 0)
        runner.submit(Job(s.drive, request, JobKind.READ, Priority.BACKGROUND, deadline, fmt,
                          future, name, index))  # fmt: skip
        return await future
