"""A finished job's value, decoded from its answer once while the answer stays the same.

A carrier keeps one decoded response for every answer of the same bytes (a parameter
that holds its value answers the same bytes at every poll), so when a parameter's answer
is the very response it decoded last time, in the same notation, its value is the one
worked out then.
"""

from __future__ import annotations

from typing import Any

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.planning.jobs import JobResult
from pkwbus.master.planning.outcomes import Answered, Outcome
from pkwbus.master.planning.transaction import Tally
from pkwbus.protocol import pkw

__all__ = ["DecodedValues", "job_result"]


def job_result(
    outcome: Outcome, tally: Tally | None, request: pkw.PkwRequest, fmt: ParameterDescription
) -> JobResult:
    """The result of a finished job: its value when the answer carries one.

    RemoteProtocolError when the answer carries a value that cannot be decoded.
    """
    if not isinstance(outcome, Answered):
        return JobResult(outcome, tally=tally)
    if not isinstance(outcome.response, pkw.ValueResponse | pkw.TextResponse):
        return JobResult(outcome, tally=tally)  # a description element, a count: no value
    raw, value = fmt.value_of(outcome.response)
    return JobResult(outcome, raw, value, tally)


# A parameter of a drive: (drive, PNU, subindex).
_Key = tuple[str, int, int]


class DecodedValues:
    """:func:`job_result`, with each parameter's last decoded answer kept: its response,
    the notation it was decoded in, its raw number and its value."""

    __slots__ = ("_last",)

    def __init__(self) -> None:
        self._last: dict[_Key, tuple[pkw.PkwResponse, ParameterDescription, int | None, Any]]
        self._last = {}

    def result(
        self, drive: str, outcome: Outcome, tally: Tally | None, request: pkw.PkwRequest,
        fmt: ParameterDescription,
    ) -> JobResult:  # fmt: skip
        """:func:`job_result` of ``drive``'s answer; RemoteProtocolError when its value
        cannot be decoded."""
        if type(outcome) is not Answered:
            return job_result(outcome, tally, request, fmt)
        response, key = outcome.response, (drive, request.pnu, request.subindex)
        last = self._last.get(key)
        if last is not None and last[0] is response and last[1] is fmt:
            return JobResult(outcome, last[2], last[3], tally)
        result = job_result(outcome, tally, request, fmt)
        if result.value is not None:
            self._last[key] = (response, fmt, result.raw, result.value)
        return result

    def forget(self, drive: str) -> None:
        """A drive gone from the line: nothing of it is kept."""
        self._last = {k: v for k, v in self._last.items() if k[0] != drive}

    def __len__(self) -> int:
        return len(self._last)
