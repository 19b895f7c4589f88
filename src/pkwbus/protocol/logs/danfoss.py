"""The Danfoss FC alarm log, read over the FC protocol: ten trips, the newest first.

15-30 Alarm Log: Error Code, 15-31 Alarm Log: Value, 15-32 Alarm Log: Time,
arrays of 10, index 0 the newest and 9 the oldest. This layout comes from a
secondary source citing the FC 300 Programming Guide (MG33MJ22, section
5.3); no vendor page confirming it was found. The index travels in IND, its
low byte only (FC 360 Design Guide, section 9.4.9, whose example is 15-30).
The unit and reference of 15-32 are not confirmed by any vendor document:
it is kept as the entry's drive time, part of what tells entries apart, and
never read as a time (``time_source`` is ``seen``). What an unused entry
reads is not stated; an error code of 0 is taken as none.

The log has no change counter: its newest entry's code and time are what is watched.
"""

from __future__ import annotations

from dataclasses import dataclass

from pkwbus.protocol.logs.model import Kind, LogEntry, Opaque, Read, SweepResult, TimeBase, Values

__all__ = ["DANFOSS_ALARM_LOG", "ENTRIES", "AlarmLog"]

ENTRIES = 10


def _code(i: int) -> Read:
    return Read(1530, i)  # 15-30 Alarm Log: Error Code


def _value(i: int) -> Read:
    return Read(1531, i)  # 15-31 Alarm Log: Value


def _time(i: int) -> Read:
    return Read(1532, i)  # 15-32 Alarm Log: Time


NEWEST = (_code(0), _value(0), _time(0))
# What is watched: the newest entry's code and time (a new trip changes its time, whatever
# the unit; two reads instead of three keep the watch cheap).
WATCHED = (_code(0), _time(0))


class _Sweep:
    """Every error code; then the value and time of each entry there; then the newest
    entry again."""

    def __init__(self) -> None:
        self.known: dict[Read, int | None] = {}
        self.newest_after: tuple[int | None, ...] | None = None
        self._round = 0

    def next(self) -> tuple[Read, ...]:
        if self._round == 0:
            return tuple(_code(i) for i in range(ENTRIES))
        if self._round == 1:
            return tuple(r for i in self._present() for r in (_value(i), _time(i)))
        if self._round == 2:
            return NEWEST
        return ()

    def feed(self, values: Values) -> None:
        if self._round == 2:
            self.newest_after = tuple(values.get(r) for r in NEWEST)
        else:
            self.known.update(values)
        self._round += 1
        if self._round == 1 and not self._present():
            self._round = 2  # an empty log: no values or times to read

    def _present(self) -> list[int]:
        return [i for i in range(ENTRIES) if self.known.get(_code(i))]

    def result(self) -> SweepResult | None:
        known = self.known
        if self._round < 3 or any(known.get(_code(i)) is None for i in range(ENTRIES)):
            return None
        before, after = tuple(known.get(r) for r in NEWEST), self.newest_after
        if after is None or after[0] != before[0] or (before[0] and after != before):
            return None  # a trip was logged while the log was read
        entries = []
        for i in self._present():
            raw_time = known.get(_time(i))
            when = Opaque(raw_time) if raw_time is not None else None
            entries.append(LogEntry(Kind.FAULT, known[_code(i)] or 0, known.get(_value(i)), when))
        return SweepResult(tuple(entries), None)


@dataclass(frozen=True, slots=True)
class AlarmLog:
    """The Danfoss FC alarm log as a :class:`~pkwbus.protocol.logs.model.DriveLog`."""

    name: str = "Danfoss alarm log"
    time_base: TimeBase = TimeBase.NONE
    runtime: tuple[Read, ...] = ()
    kinds: tuple[Kind, ...] = (Kind.FAULT,)  # a Danfoss alarm-log entry is a trip

    def watch(self) -> tuple[Read, ...]:
        return WATCHED

    def sweep(self, previous: SweepResult | None = None) -> _Sweep:
        return _Sweep()  # read whole each time: ten entries


DANFOSS_ALARM_LOG = AlarmLog()
