"""``GET /api/v1/drives``: what it answers costs what it shows.

A drive's view is made from the read model (the snapshot) by walking that
drive's own polls, never all readings, and kept as JSON until something of the
drive changes (:class:`~pkwbus.master.snapshot.Changes`): an answer joins the
kept pieces and makes only those of the drives that changed. A changed drive's
view is made again from three kept parts (its values, each value's piece made
again only when its reading or decoding changed; its head; its tail), each part
made again only when what it shows changed. A large answer is made in slices,
the event loop free between them, and joined in one copy. ``changed_since`` gives
only the drives changed after the token of an earlier answer; ``view=overview``
one short row per drive, made afresh at each answer (its age moves).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from itertools import compress
from operator import is_not
from typing import Any, Literal

from pydantic_core import to_json

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.alarms import said
from pkwbus.master.planning.plan import PollSpec
from pkwbus.master.reading import Reading
from pkwbus.protocol.pzd import status_bits
from pkwbus.service.http.models import DriveOverview, DriveView, ParameterReading
from pkwbus.service.http.views import (
    alarm_views,
    known_line,
    maintenance_view,
    settings_changed,
    settings_swept,
    slave_view,
    writable_refs,
    writable_views,
)
from pkwbus.service.http.views.pieces import (
    ValuesMade,
    head_json,
    json_list,
    piece_of,
    restamped,
)
from pkwbus.service.http.views.readable import duration, readable, time_unit
from pkwbus.service.runtime import DriveEntry, Runtime
from pkwbus.service.writes.checks import ApiError, line_mastered_elsewhere, mastered_elsewhere

__all__ = ["SLICE", "TOKEN_HEADER", "DriveViews", "Selection", "drive_view"]

TOKEN_HEADER = "X-Changes-Token"  # the token of the answer, for ?changed_since=
SLICE = 32  # drives made between two looks at the time
TURN_EVERY = 0.004  # seconds of making at most before the event loop gets a turn
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
    return DriveView(
        name=name,
        line=entry.line,
        protocol=entry.target.protocol.value,
        address=entry.target.address,
        dialect=entry.target.dialect.name,
        up=state.up if state else True,
        status_word=word,
        status=status_bits(word, entry.target.profile) if word is not None else {},
        polled=len(entry.polls),
        faults=counts.faults if counts is not None else 0,
        telegram_errors=counts.errors if counts is not None else 0,
        values=readings_of(runtime, entry),
        alarms=alarm_views(runtime, name),
        writable=writable_views(runtime, name),
        dp=slave_view(runtime, name),
        maintenance=maintenance_view(runtime, name),
        settings=settings_swept(runtime, name),
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
    decoder = runtime.drives[name].alarm_words.get((parameter, index))
    words = said(decoder, value) if decoder is not None else ""
    counts_in = time_unit(fmt)  # a duration names its own unit ("13 h")
    # The duration worked out once (it was twice: a third of a value's piece, in Fractions).
    told = None
    if counts_in and not isinstance(value, str):
        told = duration(value, counts_in, fmt.scaling.factor)
    named = told is not None and not words
    if words:
        shown = words
    elif told is not None and not (fmt.enumerates and isinstance(value, int)):
        shown = told  # what readable() says of a duration
    else:
        shown = readable(value, fmt)
    return {
        "parameter": parameter, "index": index, "value": value, "raw": reading.raw,
        "unit": fmt.unit, "timestamp": reading.timestamp, "interval": poll.every,
        "name": fmt.name, "shown": shown, "shown_unit": "" if named else fmt.unit,
        "option": fmt.option(value), "source": source,
    }  # fmt: skip


def overview_row(runtime: Runtime, name: str, now: float) -> DriveOverview:
    """One short row of the drive: where it is and on which bus, its state (a DP slave's in
    the live list too), its faults and alarms in words, its settings that differ from their
    baseline, the age of its latest value."""
    entry = runtime.drives[name]
    snap = runtime.snapshot
    state = snap.drives.get(name)
    counts = snap.counts.get(name)
    shown: Literal["up", "down", "maintenance"] = "maintenance"
    if name not in snap.maintenance:
        shown = "up" if state is None or state.up else "down"
    active = snap.alarms.get(name, ())
    landed = counts.landed if counts is not None else None
    live = snap.slaves.get(name)
    return DriveOverview(
        name=name, line=entry.line, protocol=entry.target.protocol.value,
        address=entry.target.address, state=shown,
        dp_state=live.state.value if live is not None else None,
        faults=counts.faults if counts is not None else 0,
        telegram_errors=counts.errors if counts is not None else 0,
        alarms=[a.alarm.shown for a in active if a.alarm.kind == "alarm"],
        warnings=[a.alarm.shown for a in active if a.alarm.kind != "alarm"],
        updated=landed, age=None if landed is None else max(0.0, now - landed),
        settings_changed=settings_changed(runtime, name),
    )  # fmt: skip


class DriveViews:
    """The drives' views as JSON, each kept until its drive changes."""

    def __init__(self, runtime: Runtime) -> None:
        self.runtime = runtime
        # drive -> (its change number, its entry, swept, the JSON of its view)
        self._kept: dict[str, tuple[int, DriveEntry, bool, bytes]] = {}
        self.made = 0  # views made (not taken from what was kept): for tests and benches
        # Each drive's values as they were last made.
        self._plans: dict[str, ValuesMade] = {}
        self._places: dict[str, int] = {}
        # Each drive's head: (its entry, up, status word, JSON); its tail: (its entry, what
        # it shows, JSON).
        self._heads: dict[str, tuple[DriveEntry, bool, int | None, bytes]] = {}
        self._tails: dict[str, tuple[DriveEntry, tuple[object, ...], bytes]] = {}

    def select(self, chosen: Selection) -> tuple[list[str], str]:
        """The drives the answer is of, in the configuration's order, and the token that
        marks this moment; ApiError 404 for an unknown line or drive, 409 for one another
        instance masters (hot standby)."""
        runtime = self.runtime
        changes = runtime.snapshot.changes
        token = changes.token()
        if chosen.drive is not None:
            entry = runtime.drives.get(chosen.drive)
            if entry is None:
                mastered_elsewhere(runtime, chosen.drive)
                raise ApiError(404, "unknown_drive", f"no drive is named {chosen.drive!r}")
            names: Iterable[str] = (chosen.drive,)
        elif chosen.line is not None and not known_line(runtime, chosen.line):
            line_mastered_elsewhere(runtime, chosen.line)
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
        """The JSON list of the drives' views; the loop turns between slices of them, once
        :data:`TURN_EVERY` seconds of making have passed (most answers are mostly kept
        pieces and need no turn; one made whole, after a start or a reload, needs many)."""
        pieces: list[bytes] = []
        clock = time.perf_counter
        turn_at = clock() + TURN_EVERY
        for start in range(0, len(names), SLICE):
            if start and clock() >= turn_at:
                await asyncio.sleep(0)
                turn_at = clock() + TURN_EVERY
            for name in names[start : start + SLICE]:
                if name in self.runtime.drives:  # a reload between slices may remove one
                    pieces.append(self._json(name))
        self._drop_gone()
        return json_list(pieces)

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
        return json_list(pieces)

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
        swept = settings_swept(runtime, name)
        kept = self._kept.get(name)
        if kept is not None and kept[0] == number and kept[1] is entry and kept[2] == swept:
            return kept[3]
        made = self._render(name, entry, swept)
        self.made += 1
        self._kept[name] = (number, entry, swept, made)
        return made

    def _render(self, name: str, entry: DriveEntry, swept: bool) -> bytes:
        """The JSON of the drive's view, as :func:`drive_view` gives it, in three kept parts:
        each value's piece until its reading, its decoding or the drive's entry changes; the
        head (where the drive is, up, its status word) until one of them changes; the tail
        (counts, alarms, writable parameters, DP, maintenance, settings) until what it
        shows changes."""
        snap = self.runtime.snapshot
        values = self._values_json(name, entry)
        state, counts = snap.drives.get(name), snap.counts.get(name)
        up, word = (state.up, state.status_word) if state is not None else (True, None)
        head = self._heads.get(name)
        if head is None or head[0] is not entry or head[1] != up or head[2] != word:
            head = (entry, up, word, head_json(name, entry, up, word))
            self._heads[name] = head
        faults, errors = (counts.faults, counts.errors) if counts is not None else (0, 0)
        active = snap.alarms.get(name, ())
        shown = (faults, errors, active, self._writable_now(name, entry),
                 snap.slaves.get(name), snap.maintenance.get(name), swept)  # fmt: skip
        tail = self._tails.get(name)
        if tail is None or tail[0] is not entry or tail[1] != shown:
            tail = (entry, shown, self._tail_json(name, faults, errors, swept))
            self._tails[name] = tail
        return b"".join((head[3], b'"values":[', values, b"],", tail[2]))

    def _values_json(self, name: str, entry: DriveEntry) -> bytes:
        """The JSON of the drive's polled values that landed (comma-separated), in the order
        of its polls: kept whole while none of its readings and decodings changed (each
        reading looked at once), a value's piece made again only when its reading, its
        decoding or the entry changed."""
        snap = self.runtime.snapshot
        plan = self._plans.get(name)
        if plan is None or plan.entry is not entry:
            plan = self._plans[name] = ValuesMade(entry)
        decoding = snap.decoding.get(name)
        formats = decoding.formats if decoding is not None else {}
        sources = decoding.sources if decoding is not None else {}
        readings = list(map(snap.readings.get, plan.keys))
        fmts = list(map(formats.get, plan.ats))
        told = list(map(sources.get, plan.parameters))
        if fmts == plan.fmts and told == plan.told:
            if readings == plan.readings:
                return plan.json
            # only the readings that are other objects than before
            changed: Iterable[int] = compress(
                range(len(readings)), map(is_not, readings, plan.readings)
            )
        else:
            changed = range(len(readings))
        runtime, kept, texts = self.runtime, plan.pieces, plan.texts
        for i in changed:
            reading = readings[i]
            if reading is None:
                texts[i] = b""
                continue
            fmt = fmts[i]
            if fmt is None:
                fmt = _NO_FORMAT
            source = told[i] or plan.fallback[i]
            was = kept[i]
            if (
                was is not None
                and (was[1] is fmt or was[1] == fmt)  # a decoding made again, the same
                and was[2] == source
            ):
                if was[0] is reading:
                    texts[i] = was[3]
                    continue
                piece = restamped(was, reading)  # a new reading of the same value
                if piece is not None:
                    kept[i] = (reading, fmt, source, piece, was[4], was[5])
                    texts[i] = piece
                    continue
            fields = _reading_fields(runtime, entry.polls[i], reading, fmt, source, name)
            piece, before, after = piece_of(fields)
            kept[i] = (reading, fmt, source, piece, before, after)
            texts[i] = piece
        plan.readings, plan.fmts, plan.told = readings, fmts, told
        plan.json = b",".join(filter(None, texts))
        return plan.json

    def _writable_now(self, name: str, entry: DriveEntry) -> tuple[object, ...]:
        """What the drive's writable parameters show depends on: what the drive described
        and stated of each, and the value of the latest reading it confirmed."""
        snap = self.runtime.snapshot
        decoding = snap.decoding.get(name)
        described = decoding.described if decoding is not None else {}
        stated, latest = snap.stated, snap.latest
        now: list[object] = []
        for pnu, index, _ in writable_refs(entry):
            reading = latest.get((name, pnu, index or 0))
            # its value alone is shown: a new reading of the same value changes nothing
            value = None if reading is None else reading.value
            now += (described.get(pnu), stated.get((name, pnu)), type(value), value)
        return tuple(now)

    def _tail_json(self, name: str, faults: int, errors: int, swept: bool) -> bytes:
        runtime = self.runtime
        tail = {
            "faults": faults, "telegram_errors": errors,
            "alarms": alarm_views(runtime, name), "writable": writable_views(runtime, name),
            "dp": slave_view(runtime, name), "maintenance": maintenance_view(runtime, name),
            "settings": swept,
        }  # fmt: skip
        return to_json(tail, inf_nan_mode="null")[1:]

    def _drop_gone(self) -> None:
        if len(self._kept) > len(self.runtime.drives):
            for name in [n for n in self._kept if n not in self.runtime.drives]:
                del self._kept[name]
                self._heads.pop(name, None)
                self._plans.pop(name, None)
                self._tails.pop(name, None)
