"""The logs a simulated drive keeps of its own trips and alarms: the SINAMICS fault and
alarm buffers and the Danfoss FC alarm log. Pure: the drive model passes the times.

SINAMICS fault buffer (:class:`FaultBuffer`), laid out as the SINAMICS S200 Operating
Instructions (11/2023, FW V6.3, appendix A.3, the fault buffer) describe it: 64
entries = 8 fault cases x 8 faults. Index [0..7] is the active ("actual") fault case,
faults 1..8 in the order they came (index 0 the first); [8..15] the 1st acknowledged
case; ... [56..63] the 7th acknowledged case. A fault enters the active case at the
next free place; "for more than 8 active faults, only the entries are overwritten at
the eighth position (index 7)". On acknowledgement the active case becomes the 1st
acknowledged case, the 1st the 2nd, and so on; "the last incident is rejected" (the
7th is dropped). The active case is then empty. Acknowledging with no active fault
changes nothing here (the documents do not say; the simulator's choice).

The counter of buffer changes (r0944) is incremented at every change, a fault entered
(also one overwriting the eighth place) or an acknowledgement, as the PROFIdrive
profile's P944 is ("incremented each time that the fault buffer changes", Unsigned16,
so it wraps at 65536: Nanotec PD6-E PROFINET manual, PROFIdrive object 944); a SINAMICS
page for r0944 itself was not found.

Times are the system runtime (r2114: milliseconds within the day and days; SINAMICS
CU240D-2 Operating Instructions 04/2018, section 8.2: "when a corresponding message is
triggered, the inverter transfers the parameter values r2114 to the corresponding
parameters of the alarm or fault buffer"). A fault's received time is the runtime at
its trip, its removed time the runtime at its acknowledgement, 0 while not removed.

Danfoss FC alarm log (:class:`AlarmLog`): 15-30 code, 15-31 value, 15-32 time, 10
entries, index 0 the newest and 9 the oldest. That order and length come from a
secondary source only (a third-party FC-302 troubleshooting note citing the FC 300
Programming Guide section 5.3); no vendor page confirmed them, and the simulator keeps
them so. A trip goes in at index 0, the others move down and the oldest is dropped;
an acknowledgement removes nothing.

SINAMICS alarm buffer (:class:`AlarmBuffer`): r2122 code, r2124 value, r2123/r2145 time
received (ms, days), r2125/r2146 time removed, [0..7] the alarms there, sorted by time
received, the oldest at [0]; eight there and another: [7] is overwritten (SINAMICS G120C
Operating Instructions 09/2017, section 8.3). A gone alarm moves at once into the
history [8..63], the latest at [8] (SINAMICS G220 Operating Instructions 04/2024, section
15.6: "The last alarm that was resolved has index [8]"; G120 parameter descriptions,
r2122: [63] the oldest, dropped beyond). r2121, "incremented every time the alarm buffer
changes" (Unsigned16), counts each alarm that comes and each that goes. Other SINAMICS
drives keep gone alarms at their places until the eight are full (ET 200pro FC-2
Operating Instructions 09/2017, section 10.4); the simulator keeps the G220's way, so
that [0] is always an alarm there now.

An empty entry reads 0 in every field of these logs: for the Danfoss log 0 is the usual
default of these arrays' range, not a confirmed reading; for the SINAMICS buffer it is
the simulator's choice.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Final

__all__ = [
    "ALARM_FIELDS",
    "BUFFERED_ALARM_FIELDS",
    "CASES",
    "DAY_MS",
    "FAULT_FIELDS",
    "PLACES",
    "Alarm",
    "AlarmBuffer",
    "AlarmLog",
    "BufferedAlarm",
    "Fault",
    "FaultBuffer",
    "runtime_words",
]

DAY_MS = 86_400_000  # r2114[0] goes back to 0 here and r2114[1] counts one more day
CASES = 8  # fault cases: the active one and 7 acknowledged ones
PLACES = 8  # faults per case
_COUNTER_WRAP = 1 << 16  # r0944 is Unsigned16


def runtime_words(ms: int) -> tuple[int, int]:
    """A runtime in milliseconds as r2114 shows it: (ms within the day, days)."""
    days, within = divmod(ms, DAY_MS)
    return within, days


@dataclass(frozen=True, slots=True)
class Fault:
    """One entry of the SINAMICS fault buffer; times in ms of system runtime."""

    number: int
    value: int
    received: int
    removed: int | None = None  # None while the fault is active


@dataclass(frozen=True, slots=True)
class Alarm:
    """One entry of the Danfoss alarm log; ``time`` in seconds of the drive's operating
    time (the simulator's choice: 15-32's unit and reference are not confirmed)."""

    code: int
    value: int
    time: int


def _removed(entry: Fault | BufferedAlarm, day: bool) -> int:
    return 0 if entry.removed is None else runtime_words(entry.removed)[day]


# The ``live`` names of the buffer's parameters (table.py) and what each shows of a fault.
FAULT_FIELDS: Final[Mapping[str, Callable[[Fault], int]]] = {
    "fault_number": lambda f: f.number,  # r0947
    "fault_value": lambda f: f.value,  # r0949
    "fault_received_ms": lambda f: runtime_words(f.received)[0],  # r0948
    "fault_received_days": lambda f: runtime_words(f.received)[1],  # r2130
    "fault_removed_ms": lambda f: _removed(f, False),  # r2109
    "fault_removed_days": lambda f: _removed(f, True),  # r2136
}
ALARM_FIELDS: Final[Mapping[str, Callable[[Alarm], int]]] = {
    "alarm_code": lambda a: a.code,  # 15-30
    "alarm_value": lambda a: a.value,  # 15-31
    "alarm_time": lambda a: a.time,  # 15-32
}


class FaultBuffer:
    """The SINAMICS fault buffer: ``cases[0]`` the active case, ``cases[k]`` the k-th
    acknowledged one; ``changes`` the counter r0944."""

    def __init__(self) -> None:
        self.cases: list[list[Fault]] = [[] for _ in range(CASES)]
        self.changes = 0

    def enter(self, number: int, value: int, runtime_ms: int) -> None:
        """A fault comes: into the active case's next free place, or over its eighth."""
        active = self.cases[0]
        fault = Fault(number, value, runtime_ms)
        if len(active) < PLACES:
            active.append(fault)
        else:
            active[-1] = fault
        self._changed()

    def acknowledge(self, runtime_ms: int) -> bool:
        """The active faults are acknowledged at ``runtime_ms``: the cases move one down,
        the 7th acknowledged case is dropped. False (nothing changes) with none active."""
        if not self.cases[0]:
            return False
        removed = [replace(fault, removed=runtime_ms) for fault in self.cases[0]]
        self.cases = [[], removed, *self.cases[1:-1]]
        self._changed()
        return True

    def entry(self, index: int) -> Fault | None:
        """The fault at buffer index ``index`` (0-63), None for an empty place."""
        case, place = divmod(index, PLACES)
        faults = self.cases[case] if 0 <= case < CASES else []
        return faults[place] if place < len(faults) else None

    def read(self, name: str, index: int) -> int:
        """Parameter ``name`` (a key of :data:`FAULT_FIELDS`) at ``index``; 0 when empty."""
        fault = self.entry(index)
        return 0 if fault is None else FAULT_FIELDS[name](fault)

    def _changed(self) -> None:
        self.changes = (self.changes + 1) % _COUNTER_WRAP


@dataclass(frozen=True, slots=True)
class BufferedAlarm:
    """One entry of the SINAMICS alarm buffer; times in ms of system runtime."""

    code: int
    value: int
    received: int
    removed: int | None = None  # None while the alarm is there


BUFFERED_ALARM_FIELDS: Final[Mapping[str, Callable[[BufferedAlarm], int]]] = {
    "buffered_alarm_code": lambda a: a.code,  # r2122
    "buffered_alarm_value": lambda a: a.value,  # r2124
    "buffered_alarm_received_ms": lambda a: runtime_words(a.received)[0],  # r2123
    "buffered_alarm_received_days": lambda a: runtime_words(a.received)[1],  # r2145
    "buffered_alarm_removed_ms": lambda a: _removed(a, False),  # r2125
    "buffered_alarm_removed_days": lambda a: _removed(a, True),  # r2146
}
ALARM_PLACES = 8
ALARM_ENTRIES = 64


class AlarmBuffer:
    """The SINAMICS alarm buffer: ``there`` the alarms now ([0..7], the oldest first),
    ``history`` the gone ones ([8..63], the latest first); ``changes`` the counter r2121."""

    def __init__(self) -> None:
        self.there: list[BufferedAlarm] = []
        self.history: list[BufferedAlarm] = []
        self.changes = 0

    def come(self, code: int, value: int, runtime_ms: int) -> None:
        """An alarm comes: at the next place, or over [7] when eight are there."""
        alarm = BufferedAlarm(code, value, runtime_ms)
        if len(self.there) < ALARM_PLACES:
            self.there.append(alarm)
        else:
            self.there[-1] = alarm
        self._changed()

    def go(self, code: int, runtime_ms: int) -> bool:
        """The oldest alarm ``code`` there goes into the history; False: none is there."""
        for i, alarm in enumerate(self.there):
            if alarm.code == code:
                del self.there[i]
                gone = replace(alarm, removed=runtime_ms)
                self.history = [gone, *self.history][: ALARM_ENTRIES - ALARM_PLACES]
                self._changed()
                return True
        return False

    def read(self, name: str, index: int) -> int:
        """Parameter ``name`` (a key of :data:`BUFFERED_ALARM_FIELDS`) at ``index``; 0 when
        empty."""
        if index < ALARM_PLACES:
            alarm = self.there[index] if index < len(self.there) else None
        else:
            at = index - ALARM_PLACES
            alarm = self.history[at] if at < len(self.history) else None
        return 0 if alarm is None else BUFFERED_ALARM_FIELDS[name](alarm)

    def _changed(self) -> None:
        self.changes = (self.changes + 1) % _COUNTER_WRAP


class AlarmLog:
    """The Danfoss alarm log, newest first, at most ``length`` entries."""

    def __init__(self, length: int = 10) -> None:
        self.length = length
        self.entries: list[Alarm] = []

    def enter(self, code: int, value: int, time: int) -> None:
        self.entries = [Alarm(code, value, time), *self.entries][: self.length]

    def read(self, name: str, index: int) -> int:
        """Parameter ``name`` (a key of :data:`ALARM_FIELDS`) at ``index``; 0 when empty."""
        if not 0 <= index < len(self.entries):
            return 0
        return ALARM_FIELDS[name](self.entries[index])
