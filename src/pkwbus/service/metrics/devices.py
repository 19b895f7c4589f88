"""The device-value families: parameter values, drive and line state, from the snapshot.

Read from the snapshot as it is at each scrape, so a scrape never causes bus
traffic and values that disappear also disappear from the output.
``pkwbus_parameter_info`` changes only when a drive's description of a
parameter settles (:meth:`SnapshotCollector.described`): its text is made
then, with ``pkwbus_catalog_mismatch``, the fields on which a drive
contradicts its catalog. A value's lines are made when its reading lands in the
snapshot (:meth:`SnapshotCollector.landed`, an output of the lines' streams), a
drive's when the scrape finds a new state whose lines differ; a scrape compares
what the snapshot holds with what the lines were made of, by identity, makes only
what differs, and joins again only the pieces that changed (:mod:`.rows`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

from prometheus_client.core import GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from pkwbus.master.events import Event, ValueLanded
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import DriveState, ReadingKey, Snapshot
from pkwbus.protocol.pzd import STATUS_BITS, Profile, ref_to_percent
from pkwbus.service.metrics.exposition import CHUNK
from pkwbus.service.metrics.rows import Made, Rows
from pkwbus.service.metrics.textformat import format_value, head, header, same_number

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
_HEADERS = {
    f: header(*f, "gauge").encode() for f in (VALUE, STAMP, DRIVE_UP, WORD, BIT, MAV, LINE_UP)
}


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


@dataclass(frozen=True, slots=True)
class _DriveHeads:
    """The text before the value of each of a drive's lines, made once."""

    up: tuple[bytes, bytes]  # the whole line: down, up
    word: str
    bits: tuple[tuple[int, bytes, bytes], ...]  # each named bit: its number, lines at 0, 1
    mav: str


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
        self._given = dict(self._parameters)  # as the configuration gave them
        self._mismatches: dict[tuple[str, str, str], Mismatch] = {}
        self._line_of = {p.drive: p.line for p in self._parameters.values()}
        self._line_of.update({name: d.line for name, d in self._drives.items()})
        self._info_text: bytes | None = None  # made at the next scrape after a change
        self._heads: dict[ReadingKey, tuple[str, str]] = {}
        for p in self._parameters.values():
            self._head((p.drive, p.parameter, p.index))
        # Each value's line and timestamp line; each drive's up, status word, status bits
        # and main actual value lines: in the snapshot's order, made as they land.
        self._values: Rows[ReadingKey, Reading] = Rows(2, self._reading, CHUNK)
        self._drive_rows: Rows[str, DriveState] = Rows(4, self._drive, CHUNK)
        self._drive_heads = {name: self._heads_of(name, d.line) for name, d in self._drives.items()}

    def add_drive(self, name: str, drive: DriveInfo, parameters: Iterable[ParameterInfo]) -> None:
        """A drive and its polled parameters (at the start, or added by a reload)."""
        self._drives[name] = drive
        self._line_of[name] = drive.line
        self._drive_heads[name] = self._heads_of(name, drive.line)
        self._drive_rows.drop(name)
        self.set_parameters(name, parameters)

    def set_parameters(self, drive: str, parameters: Iterable[ParameterInfo]) -> None:
        """The drive's polled parameters now (a reload): a kept one keeps its info as
        described while the configuration gives it as before, and takes the configuration's
        when that changed (its description, where the drive gives one, follows:
        :meth:`described`); the others' series go."""
        given = {p.key: p for p in parameters}
        for key in [k for k in self._parameters if k[0] == drive and k not in given]:
            del self._parameters[key]
            self._given.pop(key, None)
            self._heads.pop(key, None)
            self._values.drop(key)
        for key, info in given.items():
            if key not in self._parameters:
                self._head(key)
            elif self._given.get(key) == info:
                continue
            self._parameters[key] = self._given[key] = info
        self._info_text = None

    def forget_drive(self, drive: str) -> None:
        """Every series of ``drive`` (gone by a reload)."""
        self.set_parameters(drive, ())
        for table in (self._drives, self._line_of, self._drive_heads):
            table.pop(drive, None)
        self._drive_rows.drop(drive)
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

    def _render_info(self) -> bytes:
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
        ).encode()

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

    # -- exposition(): the same text, from the lines made as the values landed -------

    def exposition(self) -> Iterator[bytes]:
        """The text of the families, in pieces of at most ``CHUNK`` lines."""
        snap = self._snapshot
        # The lines as the snapshot is now (a copy of each column: the loop runs between
        # pieces); only a value or drive that changed unannounced is made here.
        values, stamps = self._values.sync(snap.readings)
        ups, words, bits, mavs = self._drive_rows.sync(snap.drives)
        lines = dict(snap.lines)
        yield _HEADERS[VALUE]
        yield from filter(None, values)  # the pieces made; an empty one is a place to turn
        yield _HEADERS[STAMP]
        yield from filter(None, stamps)
        if self._info_text is None:
            self._info_text = self._render_info()
        yield self._info_text
        yield _HEADERS[DRIVE_UP] + b"".join(ups)
        yield _HEADERS[WORD] + b"".join(words)
        yield _HEADERS[BIT]
        yield from filter(None, bits)
        yield _HEADERS[MAV] + b"".join(mavs)
        yield (
            _HEADERS[LINE_UP]
            + "".join(
                f"{head(LINE_UP[0], {'line': name})}{'1.0' if is_up else '0.0'}\n"
                for name, is_up in lines.items()
            ).encode()
        )

    def landed(self, key: ReadingKey, reading: Reading) -> None:
        """A new reading: its lines are made now, when its poll lands, not at the scrape."""
        self._values.update(key, reading)

    def on_events(self, events: Sequence[Event]) -> None:
        """Each value that landed (an output of the lines' streams)."""
        for event in events:
            if type(event) is ValueLanded:
                self.landed(event.key, event.reading)

    def _reading(
        self, key: ReadingKey, reading: Reading, previous: tuple[Reading, Made] | None
    ) -> Made:
        """A reading's value line and timestamp line (none for a text: in the API, not
        as numbers); the value line of the previous reading when it printed the same."""
        if isinstance(reading.value, str):
            return (b"", b"")
        heads = self._heads.get(key) or self._head(key)
        value = float(reading.value)
        if previous is not None and previous[1][0] and same_number(previous[0].value, value):
            value_line = previous[1][0]
        else:
            value_line = f"{heads[0]}{format_value(value)}\n".encode()
        return (value_line, f"{heads[1]}{format_value(reading.timestamp)}\n".encode())

    def _head(self, key: ReadingKey) -> tuple[str, str]:
        drive, parameter, index = key
        values = (self._line_of.get(drive, ""), drive, parameter, str(index))
        labels = dict(zip(_PV, values, strict=True))
        heads = self._heads[key] = (head(VALUE[0], labels), head(STAMP[0], labels))
        return heads

    def _drive(
        self, drive: str, state: DriveState, previous: tuple[DriveState, Made] | None
    ) -> Made:
        """The drive's up line, its status word and bit lines if it has a word, and its
        main actual value line if that came with the word; what did not change since
        ``previous`` is kept."""
        heads = self._drive_heads.get(drive)
        if heads is None:
            heads = self._drive_heads[drive] = self._heads_of(drive, self._line(drive))
        up = heads.up[state.up]
        word = state.status_word
        if word is None or drive not in self._drives:
            return (up, b"", b"", b"")
        mav = b""
        if previous is not None and previous[1][2] and previous[0].status_word == word:
            old, row = previous
            if old.main_actual == state.main_actual:
                return row if row[0] is up else (up, row[1], row[2], row[3])
            word_line, bits = row[1], row[2]
        else:
            word_line = f"{heads.word}{format_value(float(word))}\n".encode()
            bits = b"".join(one if word >> bit & 1 else zero for bit, zero, one in heads.bits)
        if state.main_actual is not None:
            mav = f"{heads.mav}{_percent(state.main_actual)}\n".encode()
        return (up, word_line, bits, mav)

    def _heads_of(self, drive: str, line: str) -> _DriveHeads:
        labels = {"line": line, "drive": drive}
        info = self._drives.get(drive)
        named = STATUS_BITS[info.profile].items() if info is not None else ()
        up = head(DRIVE_UP[0], labels)
        bits = []
        for bit, name in named:
            h = head(BIT[0], {**labels, "bit": name})
            bits.append((bit, f"{h}0.0\n".encode(), f"{h}1.0\n".encode()))
        return _DriveHeads(
            (f"{up}0.0\n".encode(), f"{up}1.0\n".encode()),
            head(WORD[0], labels),
            tuple(bits),
            head(MAV[0], labels),
        )


@lru_cache(maxsize=4096)
def _percent(raw: int) -> str:
    """A main actual value word's text, in percent (the same few words come again and
    again while the drives run at their speeds)."""
    return format_value(ref_to_percent(raw))
