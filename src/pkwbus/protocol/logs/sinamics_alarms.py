"""The SINAMICS alarm buffer, read over USS or PROFIBUS: eight alarms and their history.

SINAMICS G120 parameter descriptions (TIA Portal Information System, SINAMICS
G120), r2122[0...63] Alarm code: "r2122[0], r2124[0], r2123[0], r2125[0] -->
alarm 1 (the oldest)" ... "r2122[7] ... --> Alarm 8 (the latest)"; the alarms
that have gone are entered into the alarm history, "r2122[8] ... --> Alarm 1
(the latest)" ... "r2122[63] ... --> alarm 56 (the oldest)". r2124 alarm value
(Integer32), r2123 alarm time received in ms, r2145 in days (the time
"comprises r2145 (days) and r2123 (milliseconds)"). When an alarm goes into
the history differs between documents: at once (SINAMICS G220 Operating
Instructions 04/2024, section 15.6: "The last alarm that was resolved has
index [8]"), or only once the eight places are full and another alarm comes,
all gone ones together (SIMATIC ET 200pro FC-2 Operating Instructions 09/2017,
section 10.4); eight active alarms and another: [7] is overwritten (SINAMICS
G120C Operating Instructions 09/2017, section 8.3). This reader needs neither:
an entry is known by its content (kind, code, value, time received), never by
its place.

r2121 "Counter alarm buffer changes" (Unsigned16): "This counter is incremented
every time the alarm buffer changes" (the same parameter descriptions); it is
what is watched, and it is read before and after a sweep: a change meanwhile
means the sweep is read again. The descriptions of r2139 say to read the
buffer only once r0944 or r2121 shows a change, since data is entered into it
with a delay.

The eight places [0..7] are read whole at every sweep. The history only grows
at [8], its older entries moving one place down and the oldest leaving at
[63] (G220: "The last alarm that was resolved has index [8]"): so a sweep
reads the history from [8] down, an entry at a time, only until it meets the
entry the last sweep found newest there; everything below it is what the last
sweep found below it, moved down as far. A sweep with none to meet (the first,
the history cleared, more than its length new, or a newest entry whose value
or time the drive refused) reads it down to its end (the first code 0, or
[63]); so does one given no earlier sweep, which the watcher asks for now and
then, so that a history kept in another order costs time, not entries.

Times are in the drive's runtime base r2114 as the fault buffer's are (SINAMICS
G115D Operating Instructions 07/2023, section 9.2: the inverter transfers r2114
to the alarm or fault buffer when a message is triggered). What an unused
entry reads is not stated; an alarm code of 0 is taken as none.
"""

from __future__ import annotations

from dataclasses import dataclass

from pkwbus.protocol.logs.model import (
    Kind,
    LogEntry,
    Read,
    Runtime,
    SweepResult,
    TimeBase,
    Values,
)
from pkwbus.protocol.logs.sinamics import RUNTIME_DAYS, RUNTIME_MS

__all__ = ["ALARMS", "ENTRIES", "SINAMICS_ALARM_BUFFER", "AlarmBuffer"]

ALARMS = 8  # the places of the alarms themselves, [0..7]
ENTRIES = 64  # and their history, [8..63]

COUNTER = Read(2121)  # r2121 counter alarm buffer changes


def _code(i: int) -> Read:
    return Read(2122, i)  # r2122 alarm code


def _details(i: int) -> tuple[Read, Read, Read]:
    # r2124 alarm value, r2123 alarm time received (ms), r2145 alarm time received (days)
    return Read(2124, i, signed=True), Read(2123, i), Read(2145, i)


def _entry(i: int) -> tuple[Read, ...]:
    return (_code(i), *_details(i))


class _Sweep:
    """The counter, the runtime and the eight places' codes; then the details of each
    alarm there with the history's newest entry; then the history's entries one at a time
    down to the one the last sweep found newest there (or to its end); then the counter
    again."""

    def __init__(self, previous: SweepResult | None) -> None:
        self.known: dict[Read, int | None] = {}
        self.counter_after: int | None = None
        self._stage = "head"
        self._next = ALARMS  # the history's next place to read
        self._history_end = ALARMS  # the history's places read end here
        self._carried: list[tuple[int, LogEntry]] = []  # the last sweep's, moved down
        self._mark: tuple[int, LogEntry] | None = None  # the last sweep's newest in history
        self._below: list[tuple[int, LogEntry]] = []  # and the entries below it
        self._refused = False
        # Without an earlier sweep (or one that did not say where its entries stood) there
        # is no mark: the history is read down to its end, one entry at a time, which for
        # all but a nearly full history costs less than every code and then the details.
        if previous is not None and len(previous.places) == len(previous.entries):
            placed = zip(previous.places, previous.entries, strict=True)
            history = [(p, e) for p, e in placed if p >= ALARMS]
            # A mark is only met by its whole content: one whose value or time the drive
            # refused could be another alarm of the same code, so none is taken.
            if history and history[0][1].drive_time is not None and history[0][1].value is not None:
                self._mark, self._below = history[0], history[1:]

    def next(self) -> tuple[Read, ...]:
        if self._stage == "head":
            return (COUNTER, RUNTIME_MS, RUNTIME_DAYS, *(_code(i) for i in range(ALARMS)))
        if self._stage == "details":
            there = [r for i in range(ALARMS) if self.known.get(_code(i)) for r in _details(i)]
            return (*there, *_entry(self._next))
        if self._stage == "history":
            return _entry(self._next)
        if self._stage == "counter":
            return (COUNTER,)
        return ()

    def feed(self, values: Values) -> None:
        if self._stage == "counter":
            self.counter_after = values.get(COUNTER)
            self._stage = "done"
            return
        self.known.update(values)
        if self._stage == "head":
            self._stage = "details"
        else:
            self._stage = "history" if self._history_goes_on() else "counter"

    def _history_goes_on(self) -> bool:
        """After the history's place ``_next`` was read: whether the next one is needed."""
        at = self._next
        code = self.known.get(_code(at))
        self._refused = code is None  # the sweep fails
        if code is None or code == 0:
            return False  # the history's end
        self._next = self._history_end = at + 1
        if self._mark is not None and self._entry_at(at) == self._mark[1]:
            shift = at - self._mark[0]
            self._history_end = at  # the mark itself is carried, from here down
            self._carried = [
                (place + shift, entry)
                for place, entry in [self._mark, *self._below]
                if place + shift < ENTRIES
            ]
            return False
        return self._next < ENTRIES

    def _entry_at(self, i: int) -> LogEntry:
        value_read, ms_read, days_read = _details(i)
        when = Runtime.read(self.known.get(days_read), self.known.get(ms_read))
        return LogEntry(Kind.ALARM, self.known[_code(i)] or 0, self.known.get(value_read), when)

    def result(self) -> SweepResult | None:
        known = self.known
        if self._stage != "done" or self._refused:
            return None
        if any(known.get(_code(i)) is None for i in range(ALARMS)):
            return None  # its codes refused
        before = known.get(COUNTER)
        if before is None or before != self.counter_after:
            return None  # the buffer changed while it was read
        ms, days = known.get(RUNTIME_MS), known.get(RUNTIME_DAYS)
        runtime = Runtime.read(days, ms)
        # The newest first: the eight places latest first, then the history from [8] down.
        order = [*reversed(range(ALARMS)), *range(ALARMS, self._history_end)]
        found = [(i, self._entry_at(i)) for i in order if known[_code(i)]]
        found += self._carried
        return SweepResult(tuple(e for _, e in found), runtime, tuple(p for p, _ in found))


@dataclass(frozen=True, slots=True)
class AlarmBuffer:
    """The SINAMICS alarm buffer as a :class:`~pkwbus.protocol.logs.model.DriveLog`."""

    name: str = "SINAMICS alarm buffer"
    time_base: TimeBase = TimeBase.RUNTIME
    runtime: tuple[Read, ...] = (RUNTIME_MS, RUNTIME_DAYS)
    kinds: tuple[Kind, ...] = (Kind.ALARM,)

    def watch(self) -> tuple[Read, ...]:
        return (COUNTER,)

    def sweep(self, previous: SweepResult | None = None) -> _Sweep:
        return _Sweep(previous)


SINAMICS_ALARM_BUFFER = AlarmBuffer()
