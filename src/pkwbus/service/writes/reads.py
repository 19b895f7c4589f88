"""On-demand reads of one parameter, bounded per drive (and a write's read-back).

They go ahead of polls and need no token: a bound of
:data:`MAX_READS_PER_DRIVE` waiting reads per drive keeps a flood of them from
starving the drive's polls. Raises
:class:`~pkwbus.service.writes.checks.ApiError`: 429 when the bound is
reached, 404 for a parameter the dialect cannot encode, and those of the
checks (:mod:`pkwbus.service.writes.checks`) and of the job's outcome.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.planning.jobs import JobKind, JobResult
from pkwbus.master.planning.outcomes import Answered, Cancelled
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.values import ParameterRef
from pkwbus.service.runtime import DriveEntry, Runtime
from pkwbus.service.writes.checks import (
    ApiError,
    check_names,
    described_format,
    fit_index,
    locate,
    raise_for,
)

__all__ = ["MAX_READS_PER_DRIVE", "Reads", "read_request"]

MAX_READS_PER_DRIVE = 4  # on-demand reads of one drive waiting at once


def read_request(entry: DriveEntry, ref: ParameterRef, fmt: ParameterDescription) -> pkw.PkwRequest:
    """The read of ``ref`` on the drive: its text for a text parameter, else its value."""
    d = entry.target.dialect
    try:
        return pkw.read_parameter(d, ref.pnu, ref.index, text=fmt.is_text)
    except LocalProtocolError as exc:
        raise ApiError(404, "not_encodable", str(exc)) from None


class Reads:
    """The on-demand reads of a runtime, counted per drive while they wait."""

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime
        self._waiting: Counter[str] = Counter()

    async def read(self, drive: str, parameter: str, index: int | None) -> dict[str, Any]:
        check_names(drive, parameter)
        entry, ref = locate(self.runtime, drive, parameter, index)
        fmt = described_format(self.runtime, entry, ref)
        ref = fit_index(ref, fmt)
        request = read_request(entry, ref, fmt)
        if self._waiting[entry.name] >= MAX_READS_PER_DRIVE:
            raise ApiError(
                429,
                "busy",
                f"{MAX_READS_PER_DRIVE} reads of {entry.name} are already waiting:"
                " ask again when they are answered",
            )
        self._waiting[entry.name] += 1
        try:
            result = await self.runtime.submit(
                entry.name, request, JobKind.READ, fmt, parameter=ref.name, index=ref.index or 0
            )
        finally:
            self._waiting[entry.name] -= 1
        raise_for(result)
        return {
            "parameter": ref.name,
            "pnu": ref.pnu,
            "index": ref.index or 0,
            "raw": result.raw,
            "value": result.value,
            "unit": fmt.unit,
            "access": entry.access,
        }

    async def try_read(
        self, entry: DriveEntry, ref: ParameterRef, fmt: ParameterDescription
    ) -> JobResult:
        """A read whose failure is not an error: the result, with no value when unanswered.

        Not counted in the per-drive bound: it is the read-back of a write, of the drive
        written (none where a reload removed it or made it a new entry since)."""
        if self.runtime.drives.get(entry.name) is not entry:
            return JobResult(Cancelled("a reload changed the drive since: not read back"))
        request = read_request(entry, ref, fmt)
        result = await self.runtime.submit(
            entry.name, request, JobKind.READ, fmt, parameter=ref.name, index=ref.index or 0
        )
        if not isinstance(result.outcome, Answered):
            return JobResult(result.outcome)
        return result
