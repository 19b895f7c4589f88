"""Where a parameter's settled description goes in the service besides the read model (whose
writer keeps how each drive's values decode): ``pkwbus_parameter_info`` /
``pkwbus_catalog_mismatch``, and the description book kept between runs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

from pkwbus.catalog.precedence import Disagreement, resolve
from pkwbus.master.events import DescriptionChecked, Event
from pkwbus.master.planning.plan import Described, DescribedFromBook, Forgotten, Redecoded
from pkwbus.service.assembly.description_file import DescriptionFile
from pkwbus.service.metrics.devices import Mismatch, ParameterInfo, SnapshotCollector
from pkwbus.service.runtime import DriveEntry

__all__ = ["DescriptionSink"]


class DescriptionSink:
    """Takes each settled description to the metrics and the book."""

    def __init__(
        self,
        entries: Mapping[str, DriveEntry],
        collector: SnapshotCollector,
        kept: DescriptionFile | None = None,
    ) -> None:
        self._entries = entries
        self._collector = collector
        self._kept = kept

    def on_events(self, events: Sequence[Event]) -> None:
        """Each description checked (an output of the lines' streams)."""
        for event in events:
            if type(event) is DescriptionChecked:
                entry = self._entries.get(event.event.drive)
                if entry is not None:
                    self(entry.line, event.event, list(event.found))

    def __call__(self, line: str, event: Described, found: list[Disagreement]) -> None:
        told_now = not isinstance(event, DescribedFromBook | Redecoded)
        if self._kept is not None and event.identity is not None and told_now:
            self._kept.save()  # the drive described something its identity did not have
        if event.drive not in self._entries or isinstance(event, Forgotten):
            return  # gone; or another drive now, described afresh
        mismatches = [
            Mismatch(line, event.drive, event.target.parameter, d.field, d.drive, d.catalog)
            for d in found
        ]
        shown = False
        for poll in event.polls:
            fmt = poll.fmt
            source = resolve(poll.layers, event.description).source if poll.layers else "none"
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
