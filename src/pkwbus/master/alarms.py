"""A drive's active alarms and warnings, from its polled alarm words and fault numbers, as
the snapshot's writer keeps them (:attr:`pkwbus.master.snapshot.Snapshot.alarms`).

Each polled parameter that tells alarms (an alarm word, or a fault or alarm
number, as the drive's catalog's alarm table says: :mod:`pkwbus.catalog.alarms`)
is decoded when its value changes. A drive's active alarms are those its
latest readings show; each keeps the time of the reading that first showed
it. What the drive last said stands while it is away (its words are read
again when it answers). A status word's bits and a log (Danfoss 15-30) are
told in words (:func:`said`), never as active alarms.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

from pkwbus.catalog.alarms import ActiveAlarm, Alarm, AlarmDecoder, CodeTable
from pkwbus.master import told
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey

__all__ = ["DriveAlarms", "LineAlarms", "said", "tells_alarms"]


def tells_alarms(decoder: AlarmDecoder) -> bool:
    """Whether the decoder's parameter holds what is active now (not a status word's bits,
    not a log)."""
    return decoder.kind != "status" and not (isinstance(decoder, CodeTable) and not decoder.active)


def said(decoder: AlarmDecoder, value: object) -> str:
    """A polled alarm parameter's value in words: the codes and texts of the bits set or
    of the number; "none" for 0 (empty for a value that is no number)."""
    if not isinstance(value, int | float):
        return ""
    alarms = decoder.decode(int(value))
    return "; ".join(a.shown for a in alarms) if alarms else "none"


class DriveAlarms:
    """One drive's active alarms by the parameter that shows them, and the value each was
    last decoded from (the same value is not decoded again)."""

    __slots__ = ("_by_source", "_values")

    def __init__(self) -> None:
        self._by_source: dict[ReadingKey, dict[str, ActiveAlarm]] = {}
        self._values: dict[ReadingKey, int] = {}

    def landed(
        self, key: ReadingKey, decoder: AlarmDecoder, value: object, at: float
    ) -> tuple[list[Alarm], list[Alarm]] | None:
        """The alarms that came and went with a reading of ``key`` at ``at`` (None: the same
        value as before, or no number: nothing changed)."""
        if not isinstance(value, int | float):
            return None
        number = int(value)
        if self._values.get(key) == number:
            return None
        self._values[key] = number
        old = self._by_source.get(key, {})
        new: dict[str, ActiveAlarm] = {}
        came: list[Alarm] = []
        for alarm in decoder.decode(number):
            kept = old.get(alarm.code)
            new[alarm.code] = kept if kept is not None else ActiveAlarm(alarm, at)
            if kept is None:
                came.append(alarm)
        went = [gone.alarm for code, gone in old.items() if code not in new]
        if new:
            self._by_source[key] = new
        else:
            self._by_source.pop(key, None)
        return came, went

    def keep(self, keys: Collection[ReadingKey]) -> bool:
        """Only the parameters in ``keys`` are watched now; whether an active alarm left
        with the others."""
        gone = [k for k in self._values if k not in keys]
        left = False
        for key in gone:
            del self._values[key]
            left = self._by_source.pop(key, None) is not None or left
        return left

    def active(self) -> tuple[ActiveAlarm, ...]:
        """Alarms first, then warnings, oldest first."""
        found = [a for alarms in self._by_source.values() for a in alarms.values()]
        found.sort(key=lambda a: (a.alarm.kind != "alarm", a.since, a.alarm.code))
        return tuple(found)


class LineAlarms:
    """A line's watched alarm parameters (``decoders``, by reading key) and its drives'
    alarms: the snapshot's writer's, who shows :meth:`active` in the snapshot."""

    __slots__ = ("_drives", "_keys", "decoders", "line")

    def __init__(self, line: str) -> None:
        self.line = line
        self.decoders: dict[ReadingKey, AlarmDecoder] = {}
        self._keys: dict[str, tuple[ReadingKey, ...]] = {}  # each drive's keys in decoders
        self._drives: dict[str, DriveAlarms] = {}

    def watch(self, drive: str, alarms: Sequence[tuple[str, int, AlarmDecoder]]) -> bool:
        """The drive's watched parameters now (a drive added, or its polls changed); whether
        an active alarm left with a parameter no longer watched."""
        self._unwatch(drive)
        mine = {(drive, parameter, index): d for parameter, index, d in alarms}
        self.decoders.update(mine)
        self._keys[drive] = tuple(mine)
        kept = self._drives.get(drive)
        return kept is not None and kept.keep(mine.keys())

    def forget(self, drive: str) -> None:
        self._unwatch(drive)
        self._drives.pop(drive, None)

    def _unwatch(self, drive: str) -> None:
        for key in self._keys.pop(drive, ()):
            del self.decoders[key]

    def landed(self, key: ReadingKey, decoder: AlarmDecoder, reading: Reading) -> bool:
        """A watched parameter's reading: the alarms that came and went with it, told once
        each; whether the drive's active alarms changed."""
        drive = key[0]
        alarms = self._drives.get(drive)
        if alarms is None:
            alarms = self._drives[drive] = DriveAlarms()
        moved = alarms.landed(key, decoder, reading.value, reading.timestamp)
        if moved is None:
            return False  # the same value as before
        came, went = moved
        for alarm in came:
            told.alarm_came(self.line, drive, alarm)
        for alarm in went:
            told.alarm_went(self.line, drive, alarm)
        return bool(came or went)

    def active(self, drive: str) -> tuple[ActiveAlarm, ...]:
        alarms = self._drives.get(drive)
        return alarms.active() if alarms is not None else ()
