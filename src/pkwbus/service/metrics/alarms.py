"""The drives' active alarms and warnings, in words, as their alarm parameters are polled.

Each polled alarm word or fault number (a parameter the drive's catalog has
an alarm table for: :mod:`pkwbus.catalog.alarms`) is decoded as its value
lands. A drive's active alarms are those its latest readings show; each
keeps the time it was first seen. An alarm that comes or goes is a log
line, and ``pkwbus_drive_alarm{line,drive,code,text,kind}`` is 1 while it is
active, with no series otherwise. A log (Danfoss 15-30) is decoded for the
page but is not an active alarm. What the drive last said stands while it
is away (its words are read again when it answers).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

from prometheus_client import CollectorRegistry, Gauge

from pkwbus.catalog.alarms import ActiveAlarm, Alarm, CodeTable, WordTable
from pkwbus.master.events import Event, ValueLanded
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey

__all__ = ["ALARM_LABELS", "AlarmBoard", "Watched"]

log = logging.getLogger(__name__)

ALARM_LABELS = ("line", "drive", "code", "text", "kind")


@dataclass(frozen=True, slots=True)
class Watched:
    """A polled parameter that tells alarms: its drive's line and its decoder."""

    line: str
    decoder: WordTable | CodeTable


class AlarmBoard:
    """Active alarms by drive; ``landed`` takes each polled reading (the line's values)."""

    def __init__(self, watched: Mapping[ReadingKey, Watched], registry: CollectorRegistry) -> None:
        self.watched = dict(watched)
        # By drive, then by the parameter that shows them: a drive's alarms cost its own.
        self._by_source: dict[str, dict[ReadingKey, dict[str, ActiveAlarm]]] = {}
        self.gauge = Gauge(
            "pkwbus_drive_alarm",
            "1 while the drive shows this alarm or warning (code and text from the vendor's"
            " table; no series when none is active)",
            list(ALARM_LABELS),
            registry=registry,
        )

    def landed(self, key: ReadingKey, reading: Reading) -> None:
        watched = self.watched.get(key)
        if watched is None or not isinstance(reading.value, int | float):
            return
        decoder = watched.decoder
        if decoder.kind == "status" or (isinstance(decoder, CodeTable) and not decoder.active):
            return  # a status word or a log: never an active alarm
        now = decoder.decode(int(reading.value))
        drive = key[0]
        sources = self._by_source.setdefault(drive, {})
        old = sources.get(key, {})
        new: dict[str, ActiveAlarm] = {}
        for alarm in now:
            kept = old.get(alarm.code)
            new[alarm.code] = kept if kept is not None else ActiveAlarm(alarm, reading.timestamp)
            if kept is None:
                self._came(watched.line, drive, alarm)
        for code, gone in old.items():
            if code not in new:
                self._went(watched.line, drive, gone.alarm)
        sources[key] = new

    def on_events(self, events: Sequence[Event]) -> None:
        """Each value that landed (an output of the lines' streams)."""
        for event in events:
            if type(event) is ValueLanded:
                self.landed(event.key, event.reading)

    def watch(self, watched: Mapping[ReadingKey, Watched]) -> None:
        """Watch these polled parameters too (a drive added by a reload)."""
        self.watched.update(watched)

    def forget(self, drive: str, keep: Collection[ReadingKey] | None = None) -> None:
        """The drive's alarm parameters gone (a reload), all or those not in ``keep``:
        what they showed leaves with them."""
        for key in [k for k in self.watched if k[0] == drive and (keep is None or k not in keep)]:
            watched = self.watched.pop(key)
            for gone in self._by_source.get(drive, {}).pop(key, {}).values():
                with contextlib.suppress(KeyError):
                    self.gauge.remove(*self._labels(watched.line, drive, gone.alarm))
        if keep is None:
            self._by_source.pop(drive, None)

    def said(self, key: ReadingKey, value: object) -> str:
        """A polled alarm parameter's value in words (empty for any other parameter): the
        codes and texts of the bits set or of the number; "none" for 0."""
        watched = self.watched.get(key)
        if watched is None or not isinstance(value, int | float):
            return ""
        alarms = watched.decoder.decode(int(value))
        return "; ".join(a.shown for a in alarms) if alarms else "none"

    def active(self, drive: str) -> list[ActiveAlarm]:
        """The drive's active alarms and warnings, alarms first, oldest first."""
        found = [a for alarms in self._by_source.get(drive, {}).values() for a in alarms.values()]
        return sorted(found, key=lambda a: (a.alarm.kind != "alarm", a.since, a.alarm.code))

    def _labels(self, line: str, drive: str, alarm: Alarm) -> tuple[str, ...]:
        return (line, drive, alarm.code, alarm.text, alarm.kind)

    def _came(self, line: str, drive: str, alarm: Alarm) -> None:
        self.gauge.labels(*self._labels(line, drive, alarm)).set(1)
        ctx = {"line": line, "drive": drive}
        log.warning("drive %s: %s %s (%s)", drive, alarm.kind, alarm.shown, alarm.parameter,
                    extra=ctx)  # fmt: skip

    def _went(self, line: str, drive: str, alarm: Alarm) -> None:
        with contextlib.suppress(KeyError):  # set when it came: there to remove
            self.gauge.remove(*self._labels(line, drive, alarm))
        ctx = {"line": line, "drive": drive}
        log.info("drive %s: %s %s is gone", drive, alarm.kind, alarm.shown, extra=ctx)
