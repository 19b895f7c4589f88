"""``GET /api/v1/drives``: what it answers costs what it shows.

A drive's view is made from the read model (the snapshot) by walking that
drive's own polls, never all readings, and kept as JSON until something of the
drive changes (:class:`~pkwbus.master.snapshot.Changes`): an answer joins the
kept pieces and makes only those of the drives that changed. A large answer
is made in slices, the event loop free between them. ``changed_since`` gives
only the drives changed after the token of an earlier answer; ``view=overview``
one short row per drive, made afresh at each answer (its age moves).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from pydantic_core import to_json

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.planning.plan import PollSpec
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey
from pkwbus.protocol.pzd import status_bits
from pkwbus.service.http.models import DriveOverview, DriveView, ParameterReading
from pkwbus.service.http.views import (
    alarm_views,
    maintenance_view,
    slave_view,
    writable_views,
)
from pkwbus.service.http.views.readable import duration, readable, time_unit
from pkwbus.service.runtime import DriveEntry, Runtime
from pkwbus.service.writes.checks import ApiError

__all__ = ["SLICE", "TOKEN_HEADER", "DriveViews", "Selection", "drive_view"]

TOKEN_HEADER = "X-Changes-Token"  # the token of the answer, for ?changed_since=
SLICE = 32  # drives made between two turns of the event loop
_NO_FORMAT = ParameterDescription()
_VIEW = DriveView.__pydantic_serializer__
_ROW = DriveOverview.__pydantic_serializer__


@dataclass(frozen=True, slots=True)
class Selection:
    """Which drives an answer is of: the query's ``line``, ``drive`` and ``changed_since``."""

    line: str | None = None
    drive: str | None = None
    changed_since: str | None = None


def drive_view(runtime: Runtime, name: str) -> DriveView:
    """The drive as the API shows it now (KeyError: no such drive)."""
    entry = runtime.drives[name]
    snap = runtime.snapshot
    state = snap.drives.get(name)
    counts = snap.counts.get(name)
    word = state.status_word if state else None
    settings = runtime.settings
    return DriveView(
        name=name,
        line=entry.line,
        protocol=entry.target.protocol.value,
        address=entry.target.address,
        dialect=entry.target.dialect.name,
        up=state.up if state else True,
        status_word=word,
        status=status_bits(word, entry.target.profile) if word is not None else {},
        faults=counts.faults if counts is not None else 0,
        telegram_errors=counts.errors if counts is not None else 0,
        values=readings_of(runtime, entry),
        alarms=alarm_views(runtime, name),
        writable=writable_views(runtime, name),
        dp=slave_view(runtime, name),
        maintenance=maintenance_view(runtime, name),
        settings=settings is not None and name in settings.swept,
    )


def readings_of(runtime: Runtime, entry: DriveEntry) -> list[ParameterReading]:
    """The drive's polled values, in the order of its polls (the same on every drive of a
    catalog): each reading of it looked at once."""
    return [
        ParameterReading.model_construct(**_reading_fields(runtime, *polled))
        for polled in _polled(runtime, entry)
    ]


Polled = tuple[PollSpec, Reading, ParameterDescription, str, str]


def _polled(runtime: Runtime, entry: DriveEntry) -> Iterator[Polled]:
    """Each polled value of the drive that landed, in the order of its polls: its poll, its
    reading, how it is decoded now, where that came from, the drive's name."""
    name = entry.name
    readings = runtime.snapshot.readings
    decoding = runtime.snapshot.decoding.get(name)
    formats = decoding.formats if decoding is not None else {}
    sources = decoding.sources if decoding is not None else {}
    for poll in entry.polls:
        parameter, index = poll.parameter, poll.index
        reading = readings.get((name, parameter, index))
        if reading is not None:
            fmt = formats.get((parameter, index), _NO_FORMAT)
            source = sources.get(parameter) or entry.sources.get(parameter, "none")
            yield poll, reading, fmt, source, name


def _reading_fields(
    runtime: Runtime,
    poll: PollSpec,
    reading: Reading,
    fmt: ParameterDescription,
    source: str,
    name: str,
) -> dict[str, Any]:
    """A ParameterReading's fields."""
    parameter, index, value = poll.parameter, poll.index, reading.value
    board = runtime.alarms
    words = board.said((name, parameter, index), value) if board is not None else ""
    shown = words or readable(value, fmt)
    counts_in = time_unit(fmt)  # a duration names its own unit ("13 h")
    named = bool(counts_in) and not words and not isinstance(value, str)
    named = named and duration(float(value), counts_in, fmt.scaling.factor) is not None
    return {
        "parameter": parameter, "index": index, "value": value, "raw": reading.raw,
        "unit": fmt.unit, "timestamp": reading.timestamp, "interval": poll.every,
        "name": fmt.name, "shown": shown, "shown_unit": "" if named else fmt.unit,
        "option": fmt.option(value), "source": source,
    }  # fmt: skip


def overview_row(runtime: Runtime, name: str, now: float) -> DriveOverview:
    """One short row of the drive: where it is, its state, its faults and alarms in words,
    the age of its latest value."""
    entry = runtime.drives[name]
    snap = runtime.snapshot
    state = snap.drives.get(name)
    counts = snap.counts.get(name)
    shown: Literal["up", "down", "maintenance"] = "maintenance"
    if name not in snap.maintenance:
        shown = "up" if state is None or state.up else "down"
    board = runtime.alarms
    active = board.active(name) if board is not None else []
    landed = counts.landed if counts is not None else None
    return DriveOverview(
        name=name, line=entry.line, address=entry.target.address, state=shown,
        faults=counts.faults if counts is not None else 0,
        telegram_errors=counts.errors if counts is not None else 0,
        alarms=[a.alarm.shown for a in active if a.alarm.kind == "alarm"],
        warnings=[a.alarm.shown for a in active if a.alarm.kind != "alarm"],
        updated=landed, age=None if landed is None else max(0.0, now - landed),
    )  # fmt: skip


class DriveViews:
    """The drives' views as JSON, each kept until its drive changes."""

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime
        # drive -> (its change number, its entry, swept, the JSON of its view)
        self._kept: dict[str, tuple[int, DriveEntry, bool, bytes]] = {}
        self.made = 0  # views made (not taken from what was kept): for tests and benches
        # Each value's JSON piece: (its reading, its decoding, the entry, its source, piece).
        self._values: dict[ReadingKey, tuple[Reading, ParameterDescription, DriveEntry, str,
                                             bytes]] = {}  # fmt: skip
        self._places: dict[str, int] = {}

    def select(self, chosen: Selection) -> tuple[list[str], str]:
        """The drives the answer is of, in the configuration's order, and the token that
        marks this moment; ApiError 404 for an unknown line or drive."""
        runtime = self.runtime
        changes = runtime.snapshot.changes
        token = changes.token()
        if chosen.drive is not None:
            entry = runtime.drives.get(chosen.drive)
            if entry is None:
                raise ApiError(404, "unknown_drive", f"no drive is named {chosen.drive!r}")
            names: Iterable[str] = (chosen.drive,)
        elif chosen.line is not None and chosen.line not in runtime.runners:
            raise ApiError(404, "unknown_line", f"no line is named {chosen.line!r}")
        else:
            names = runtime.drives
        if chosen.changed_since is not None:
            changed = changes.since(chosen.changed_since)
            if changed is not None and chosen.drive is None:  # only those, in order
                present = [n for n in changed if n in runtime.drives]
                names = sorted(present, key=self._order(present).__getitem__)
            elif changed is not None:
                names = [n for n in names if n in changed]
        if chosen.line is not None:
            drives = runtime.drives
            names = [n for n in names if drives[n].line == chosen.line]
        return list(names), token

    async def full(self, names: Sequence[str]) -> bytes:
        """The JSON list of the drives' views; the loop turns between slices of them."""
        pieces: list[bytes] = []
        for start in range(0, len(names), SLICE):
            if start:
                await asyncio.sleep(0)
            for name in names[start : start + SLICE]:
                if name in self.runtime.drives:  # a reload between slices may remove one
                    pieces.append(self._json(name))
        self._drop_gone()
        return b"[" + b",".join(pieces) + b"]"

    async def overview(self, names: Sequence[str]) -> bytes:
        """The JSON list of the drives' overview rows."""
        now = time.time()
        pieces: list[bytes] = []
        for start in range(0, len(names), 4 * SLICE):
            if start:
                await asyncio.sleep(0)
            for name in names[start : start + 4 * SLICE]:
                if name in self.runtime.drives:
                    pieces.append(_ROW.to_json(overview_row(self.runtime, name, now)))
        return b"[" + b",".join(pieces) + b"]"

    def _order(self, needed: Iterable[str]) -> dict[str, int]:
        """Each drive's place in the configuration (made again when a drive is not in it:
        one a reload added)."""
        places = self._places
        if any(n not in places for n in needed):
            places = self._places = {n: i for i, n in enumerate(self.runtime.drives)}
        return places

    def _json(self, name: str) -> bytes:
        runtime = self.runtime
        number = runtime.snapshot.changes.number_of(name)
        entry = runtime.drives[name]
        swept = runtime.settings is not None and name in runtime.settings.swept
        kept = self._kept.get(name)
        if kept is not None and kept[0] == number and kept[1] is entry and kept[2] == swept:
            return kept[3]
        made = self._render(name, entry, swept)
        self.made += 1
        self._kept[name] = (number, entry, swept, made)
        return made

    def _render(self, name: str, entry: DriveEntry, swept: bool) -> bytes:
        """The JSON of the drive's view, as :func:`drive_view` gives it, each value's piece
        kept until its reading, its decoding or the drive's entry changes."""
        runtime, snap, kept = self.runtime, self.runtime.snapshot, self._values
        pieces = []
        for polled in _polled(runtime, entry):
            poll, reading, fmt, source, _ = polled
            key = (name, poll.parameter, poll.index)
            was = kept.get(key)
            if was is not None and was[:3] == (reading, fmt, entry) and was[3] == source:
                pieces.append(was[4])
                continue
            piece = to_json(_reading_fields(runtime, *polled), inf_nan_mode="null")
            kept[key] = (reading, fmt, entry, source, piece)
            pieces.append(piece)
        state, counts = snap.drives.get(name), snap.counts.get(name)
        word = state.status_word if state else None
        head = {
            "name": name, "line": entry.line, "protocol": entry.target.protocol.value,
            "address": entry.target.address, "dialect": entry.target.dialect.name,
            "up": state.up if state else True, "status_word": word,
            "status": status_bits(word, entry.target.profile) if word is not None else {},
        }  # fmt: skip
        tail = {
            "faults": counts.faults if counts is not None else 0,
            "telegram_errors": counts.errors if counts is not None else 0,
            "alarms": alarm_views(runtime, name), "writable": writable_views(runtime, name),
            "dp": slave_view(runtime, name), "maintenance": maintenance_view(runtime, name),
            "settings": swept,
        }  # fmt: skip
        values = b'"values":[' + b",".join(pieces) + b"],"
        return to_json(head)[:-1] + b"," + values + to_json(tail, inf_nan_mode="null")[1:]

    def _drop_gone(self) -> None:
        if len(self._kept) > len(self.runtime.drives):
            for name in [n for n in self._kept if n not in self.runtime.drives]:
                del self._kept[name]
