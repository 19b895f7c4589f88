"""Where a parameter's settled description goes in the service: the drive's table (what the
API decodes and checks writes by) and ``pkwbus_parameter_info`` / ``pkwbus_catalog_mismatch``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

from pkwbus.catalog.precedence import Disagreement, resolve
from pkwbus.master.planning.plan import Described
from pkwbus.service.assembly.description_file import DescriptionFile
from pkwbus.service.metrics.devices import Mismatch, ParameterInfo, SnapshotCollector
from pkwbus.service.runtime import DriveEntry

__all__ = ["DescriptionSink"]


class DescriptionSink:
    """Takes each settled description to the drive's entry and to the metrics."""

    def __init__(
        self,
        entries: Mapping[str, DriveEntry],
        collector: SnapshotCollector,
        kept: DescriptionFile | None = None,
    ) -> None:
        self._entries = entries
        self._collector = collector
        self._kept = kept

    def __call__(self, line: str, event: Described, found: list[Disagreement]) -> None:
        if self._kept is not None and event.identity is not None and not event.from_book:
            self._kept.save()  # the drive described something its identity did not have
        entry = self._entries.get(event.drive)
        if entry is None:
            return
        if event.forgotten:  # another drive now: nothing goes to it until it is described
            entry.pending.add(event.target.pnu)
            entry.described.pop(event.target.pnu, None)
            return
        entry.pending.discard(event.target.pnu)
        if event.description is not None:
            entry.described[event.target.pnu] = event.description
        else:
            entry.described.pop(event.target.pnu, None)
        mismatches = [
            Mismatch(line, event.drive, event.target.parameter, d.field, d.drive, d.catalog)
            for d in found
        ]
        shown = False
        for poll in event.polls:
            fmt = poll.fmt
            source = resolve(poll.layers, event.description).source if poll.layers else "none"
            entry.units[poll.parameter] = fmt.unit
            entry.sources[poll.parameter] = source
            entry.formats[(poll.parameter, poll.index)] = fmt
            info = ParameterInfo(
                line, event.drive, poll.parameter, poll.index, poll.request.pnu, fmt.name,
                fmt.unit, fmt.vtype.value if fmt.vtype else "raw", source,
            )  # fmt: skip
            self._collector.described(info, mismatches)
            shown = True
        if not shown:  # a writable parameter that is not polled: its mismatches alone
            self._collector.described(
                replace(_NOT_POLLED, line=line, drive=event.drive,
                        parameter=event.target.parameter), mismatches,
            )  # fmt: skip


_NOT_POLLED = ParameterInfo("", "", "", -1, 0, "", "", "")
