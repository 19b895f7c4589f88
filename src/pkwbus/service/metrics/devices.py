"""The device-value families: parameter values, drive and line state, from the snapshot.

Built from a copy of the snapshot at each scrape, so a scrape never causes
bus traffic and values that disappear also disappear from the output.
``pkwbus_parameter_info`` changes only when a drive's description of a
parameter settles (:meth:`SnapshotCollector.described`): its text is made
then, with ``pkwbus_catalog_mismatch``, the fields on which a drive
contradicts its catalog. A value's lines are made when its reading lands in the snapshot
(:meth:`SnapshotCollector.landed`, called by the line's metrics), so that a
scrape only joins them; a drive's lines are made again only when its state
changed (see :mod:`pkwbus.service.metrics.exposition`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from itertools import islice

from prometheus_client.core import GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from pkwbus.master.events import Event, ValueLanded
from pkwbus.master.snapshot import DriveState, Reading, ReadingKey, Snapshot
from pkwbus.protocol.pzd import STATUS_BITS, Profile, ref_to_percent
from pkwbus.service.metrics.exposition import CHUNK, format_value, head, header

__all__ = ["MISMATCH_LABELS", "DriveInfo", "Mismatch", "ParameterInfo", "SnapshotCollector"]

_PV = ("line", "drive", "parameter", "index")
_INFO = (*_PV, "pnu", "name", "unit", "type", "source")
MISMATCH_LABELS = ("line", "drive", "parameter", "field", "drive_value", "catalog_value")
_LD = ("line", "drive")

VALUE = ("pkwbus_parameter_value", "Latest value read from the drive, scaled")
STAMP = ("pkwbus_parameter_last_update_timestamp_seconds", "When the value was read (Unix time)")
INFO = (
    "pkwbus_parameter_info",
    "PNU, name, unit and type of each polled parameter, and where its description came from",
)
MISMATCH = (
    "pkwbus_catalog_mismatch",
    "1 for each field on which a drive's description of a parameter contradicts its catalog",
)
DRIVE_UP = ("pkwbus_drive_up", "1 while the drive answers, else 0")
WORD = ("pkwbus_drive_status_word", "Last raw status word")
BIT = ("pkwbus_drive_status_bit", "Each named bit of the last status word")
MAV = (
    "pkwbus_drive_main_actual_percent",
    "Last main actual value (second process data word), percent of nominal",
)
LINE_UP = ("pkwbus_line_up", "1 while the port is open")


@dataclass(frozen=True)
class ParameterInfo:
    """What ``pkwbus_parameter_info`` says of one polled parameter."""

    line: str
    drive: str
    parameter: str
    index: int
    pnu: int
    name: str
    unit: str
    type: str
    source: str = "catalog"  # config, drive, catalog, none (catalog.precedence.SOURCES)

    def labels(self) -> list[str]:
        return [self.line, self.drive, self.parameter, str(self.index), str(self.pnu),
                self.name, self.unit, self.type, self.source]  # fmt: skip

    @property
    def key(self) -> ReadingKey:
        return (self.drive, self.parameter, self.index)


@dataclass(frozen=True)
class Mismatch:
    """One field on which a drive contradicts its catalog (``pkwbus_catalog_mismatch``)."""

    line: str
    drive: str
    parameter: str
    field: str
    drive_value: str
    catalog_value: str

    def labels(self) -> list[str]:
        return [self.line, self.drive, self.parameter, self.field, self.drive_value,
                self.catalog_value]  # fmt: skip


@dataclass(frozen=True)
class DriveInfo:
    line: str
    profile: Profile


_DriveKey = tuple[str, bool, int | None, int | None]  # line, up, status word, main actual


@dataclass(frozen=True, slots=True)
class _DriveLines:
    """A drive's rendered lines: up, status word, status bits, main actual value."""

    up: str
    word: str = ""
    bits: tuple[str, ...] = ()
    mav: str = ""


def _same_number(old: float | str, value: float) -> bool:
    """Whether ``old`` prints as ``value`` does: a number equal to it and of the same
    sign (-0.0 is printed as such, though it equals 0.0); never a text."""
    if isinstance(old, str):
        return False
    number = float(old)
    return number == value and math.copysign(1.0, number) == math.copysign(1.0, value)


@dataclass(frozen=True, slots=True)
class _DriveHeads:
    """The text before the value of each of a drive's lines, made once."""

    up: str
    word: str
    bits: tuple[tuple[int, str], ...]  # (bit number, head) of each named bit
    mav: str


_Rendered = tuple[Reading, str, str]  # the reading, its value line, its timestamp line
# Drives whose lines are brought up to date between two turns of the event loop.
DRIVES_A_TURN = 100


class SnapshotCollector(Collector):
    """Builds the device-value families from a copy of the snapshot."""

    def __init__(
        self,
        snapshot: Snapshot,
        drives: Mapping[str, DriveInfo],
        parameters: Iterable[ParameterInfo],
    ) -> None:
        self._snapshot = snapshot
        self._drives = dict(drives)
        self._parameters = {p.key: p for p in parameters}
        self._mismatches: dict[tuple[str, str, str], Mismatch] = {}
        self._line_of = {p.drive: p.line for p in self._parameters.values()}
        self._line_of.update({name: d.line for name, d in self._drives.items()})
        self._info_text: str | None = None  # made at the next scrape after a change
        self._heads: dict[ReadingKey, tuple[str, str]] = {}
        for p in self._parameters.values():
            self._head((p.drive, p.parameter, p.index))
        self._readings: dict[ReadingKey, _Rendered] = {}
        self._drive_lines: dict[str, tuple[_DriveKey, _DriveLines]] = {}
        self._drive_heads = {name: self._heads_of(name, d.line) for name, d in self._drives.items()}

    def add_drive(self, name: str, drive: DriveInfo, parameters: Iterable[ParameterInfo]) -> None:
        """A drive and its polled parameters (at the start, or added by a reload)."""
        self._drives[name] = drive
        self._line_of[name] = drive.line
        self._drive_heads[name] = self._heads_of(name, drive.line)
        self._drive_lines.pop(name, None)
        self.set_parameters(name, parameters)

    def set_parameters(self, drive: str, parameters: Iterable[ParameterInfo]) -> None:
        """The drive's polled parameters now (a reload): a kept one keeps its info as
        described, the others' series go."""
        given = {p.key: p for p in parameters}
        for key in [k for k in self._parameters if k[0] == drive and k not in given]:
            del self._parameters[key]
            self._heads.pop(key, None)
            self._readings.pop(key, None)
        for key, info in given.items():
            if key not in self._parameters:
                self._parameters[key] = info
                self._head(key)
        self._info_text = None

    def forget_drive(self, drive: str) -> None:
        """Every series of ``drive`` (gone by a reload)."""
        self.set_parameters(drive, ())
        for table in (self._drives, self._line_of, self._drive_heads, self._drive_lines):
            table.pop(drive, None)
        for key in [k for k in self._mismatches if k[0] == drive]:
            del self._mismatches[key]

    def described(self, info: ParameterInfo, mismatches: Iterable[Mismatch]) -> None:
        """A polled parameter's description settled (``info``), and the fields on which its
        drive contradicts the catalog (none when it agrees)."""
        if info.key in self._parameters:
            self._parameters[info.key] = info
        key = (info.drive, info.parameter)
        for old in [k for k in self._mismatches if k[:2] == key]:
            del self._mismatches[old]
        for m in mismatches:
            self._mismatches[(m.drive, m.parameter, m.field)] = m
        self._info_text = None  # a start-up settles thousands: rendered once, when scraped

    def _render_info(self) -> str:
        info = header(*INFO, "gauge") + "".join(
            f"{head(INFO[0], dict(zip(_INFO, p.labels(), strict=True)))}1.0\n"
            for p in self._parameters.values()
        )
        return (
            info
            + header(*MISMATCH, "gauge")
            + "".join(
                f"{head(MISMATCH[0], dict(zip(MISMATCH_LABELS, m.labels(), strict=True)))}1.0\n"
                for m in self._mismatches.values()
            )
        )

    def _line(self, drive: str) -> str:
        info = self._drives.get(drive)
        return info.line if info else self._line_of.get(drive, "")

    # -- collect(): the same series as prometheus_client families ---------------

    def describe(self) -> list[Metric]:
        return list(self._families(Snapshot()))

    def collect(self) -> Iterator[Metric]:
        return self._families(self._snapshot.copy())

    def _families(self, snap: Snapshot) -> Iterator[Metric]:
        value = GaugeMetricFamily(*VALUE, labels=_PV)
        stamp = GaugeMetricFamily(*STAMP, labels=_PV)
        for (drive, parameter, index), reading in snap.readings.items():
            if isinstance(reading.value, str):
                continue  # text values appear in the API, not as numbers
            labels = [self._line_of.get(drive, ""), drive, parameter, str(index)]
            value.add_metric(labels, float(reading.value))
            stamp.add_metric(labels, reading.timestamp)
        yield value
        yield stamp
        info = GaugeMetricFamily(*INFO, labels=_INFO)
        for p in self._parameters.values():
            info.add_metric(p.labels(), 1.0)
        yield info
        mismatch = GaugeMetricFamily(*MISMATCH, labels=MISMATCH_LABELS)
        for m in self._mismatches.values():
            mismatch.add_metric(m.labels(), 1.0)
        yield mismatch
        up = GaugeMetricFamily(*DRIVE_UP, labels=_LD)
        word = GaugeMetricFamily(*WORD, labels=_LD)
        bits = GaugeMetricFamily(*BIT, labels=[*_LD, "bit"])
        mav = GaugeMetricFamily(*MAV, labels=_LD)
        for drive, state in snap.drives.items():
            drive_info = self._drives.get(drive)
            line = self._line(drive)
            up.add_metric([line, drive], 1.0 if state.up else 0.0)
            if state.status_word is None or drive_info is None:
                continue
            word.add_metric([line, drive], float(state.status_word))
            for bit, name in STATUS_BITS[drive_info.profile].items():
                bits.add_metric([line, drive, name], float(state.status_word >> bit & 1))
            if state.main_actual is not None:
                mav.add_metric([line, drive], ref_to_percent(state.main_actual))
        yield up
        yield word
        yield bits
        yield mav
        line_up = GaugeMetricFamily(*LINE_UP, labels=["line"])
        for line_name, is_up in snap.lines.items():
            line_up.add_metric([line_name], 1.0 if is_up else 0.0)
        yield line_up

    # -- exposition(): the same text, from cached lines ---------------------------

    def exposition(self) -> Iterator[str]:
        """The text of the families, in pieces of at most ``CHUNK`` lines."""
        snap = self._snapshot
        # Copies (of the dicts, not their entries): the loop runs between pieces.
        readings = dict(snap.readings)
        drives = dict(snap.drives)
        lines = dict(snap.lines)
        cache = self._readings
        stamps: list[str] = []
        yield header(*VALUE, "gauge")
        entries = iter(readings.items())
        for _ in range(0, len(readings), CHUNK):
            values: list[str] = []
            for key, reading in islice(entries, CHUNK):
                rendered = cache.get(key)
                if rendered is None or rendered[0] is not reading:
                    rendered = self._reading(key, reading)
                values.append(rendered[1])
                stamps.append(rendered[2])
            yield "".join(values)
        yield header(*STAMP, "gauge")
        for start in range(0, len(stamps), CHUNK):
            yield "".join(stamps[start : start + CHUNK])
        if self._info_text is None:
            self._info_text = self._render_info()
        yield self._info_text
        ups: list[str] = []
        words: list[str] = []
        bits: list[str] = []
        mavs: list[str] = []
        for count, (drive, state) in enumerate(drives.items(), 1):
            drive_lines = self._drive(drive, state)
            ups.append(drive_lines.up)
            words.append(drive_lines.word)
            bits.extend(drive_lines.bits)
            mavs.append(drive_lines.mav)
            if count % DRIVES_A_TURN == 0:
                yield ""  # a turn of the event loop (see exposition.render)
        yield header(*DRIVE_UP, "gauge") + "".join(ups)
        yield header(*WORD, "gauge") + "".join(words)
        yield header(*BIT, "gauge")
        yield "".join(bits)
        yield header(*MAV, "gauge") + "".join(mavs)
        yield header(*LINE_UP, "gauge") + "".join(
            f"{head(LINE_UP[0], {'line': name})}{'1.0' if is_up else '0.0'}\n"
            for name, is_up in lines.items()
        )

    def landed(self, key: ReadingKey, reading: Reading) -> None:
        """A new reading: its lines are made now, when its poll lands, not at the scrape."""
        self._reading(key, reading)

    def on_events(self, events: Sequence[Event]) -> None:
        """Each value that landed (an output of the lines' streams)."""
        for event in events:
            if type(event) is ValueLanded:
                self.landed(event.key, event.reading)

    def _reading(self, key: ReadingKey, reading: Reading) -> _Rendered:
        rendered = self._readings.get(key)
        if isinstance(reading.value, str):  # text values appear in the API, not as numbers
            rendered = self._readings[key] = (reading, "", "")
            return rendered
        heads = self._heads.get(key) or self._head(key)
        value = float(reading.value)  # text values are skipped before
        if rendered is not None and _same_number(rendered[0].value, value):
            value_line = rendered[1]
        else:
            value_line = f"{heads[0]}{format_value(value)}\n"
        rendered = (reading, value_line, f"{heads[1]}{format_value(reading.timestamp)}\n")
        self._readings[key] = rendered
        return rendered

    def _head(self, key: ReadingKey) -> tuple[str, str]:
        drive, parameter, index = key
        values = (self._line_of.get(drive, ""), drive, parameter, str(index))
        labels = dict(zip(_PV, values, strict=True))
        heads = self._heads[key] = (head(VALUE[0], labels), head(STAMP[0], labels))
        return heads

    def _drive(self, drive: str, state: DriveState) -> _DriveLines:
        """The drive's up line, its status word and bit lines if it has a word, and its
        main actual value line if that came with the word; only what changed is made
        again."""
        line = self._line(drive)
        key = (line, state.up, state.status_word, state.main_actual)
        cached = self._drive_lines.get(drive)
        if cached is not None and cached[0] == key:
            return cached[1]
        heads = self._drive_heads.get(drive)
        if heads is None:
            heads = self._drive_heads[drive] = self._heads_of(drive, line)
        up = f"{heads.up}{'1.0' if state.up else '0.0'}\n"
        word = state.status_word
        result = _DriveLines(up)
        if word is not None and drive in self._drives:
            if cached is not None and cached[0][2] == word and cached[1].bits:
                word_line, bits = cached[1].word, cached[1].bits
            else:
                word_line = f"{heads.word}{format_value(float(word))}\n"
                bits = tuple(f"{h}{'1.0' if word >> bit & 1 else '0.0'}\n" for bit, h in heads.bits)
            mav = ""
            if state.main_actual is not None:
                mav = f"{heads.mav}{format_value(ref_to_percent(state.main_actual))}\n"
            result = _DriveLines(up, word_line, bits, mav)
        self._drive_lines[drive] = (key, result)
        return result

    def _heads_of(self, drive: str, line: str) -> _DriveHeads:
        labels = {"line": line, "drive": drive}
        info = self._drives.get(drive)
        named = STATUS_BITS[info.profile].items() if info is not None else ()
        return _DriveHeads(
            head(DRIVE_UP[0], labels),
            head(WORD[0], labels),
            tuple((bit, head(BIT[0], {**labels, "bit": name})) for bit, name in named),
            head(MAV[0], labels),
        )
