"""The MICROMASTER 4 fault buffer (MM420, MM430, MM440), read over USS or PROFIBUS: the
last four trips, up to two faults each.

r0947[8], the fault numbers, two per trip: [0]/[1] the recent trip (its first and its
second active fault), [2]/[3] trip -1, [4]/[5] trip -2, [6]/[7] trip -3; an
acknowledgement moves each pair down to the next pair of indexes and resets [0]/[1] to 0.
So the SED2 Operating Instructions (Siemens Building Technologies, "Troubleshooting",
"Reading Faults", p. 85) word it for the SED2, a drive of the MICROMASTER 4 parameter
set; that MICROMASTER 4 keeps r0947 so is inferred from it (no MICROMASTER page on r0947
was reachable). r0948[12] "CO: Fault time", U16: three words per trip, [0..2] the recent
trip, [3..5] trip -1, [6..8] trip -2, [9..11] trip -3, taken from the run time counter
r2114: seconds high word, seconds low word, 0 (MICROMASTER 440 Parameter List
6SE6400-5BB00-0BP0, issue 01/06, r0948). r2114[2] "Run time counter", U16: seconds =
r2114[0] x 65536 + r2114[1], "the total time the drive has been powered up", saved when
the power goes and restored at power-up (the same list, r2114). Where P2115, the AOP
real-time clock, is set (not 0), r0948 takes P2115[0..2] instead of r2114 (the same
list, r0948; a drive without the clock refuses P2115, the same list, P2115); how those
three words encode a time was not found, so such an entry's time is kept as an opaque
number, part of what tells entries apart, never read as a time (``seen``). A third word
other than 0 is not the layout r2114 gives either: opaque too. r0949 holds the fault
values beside r0947 (its size was not found: a value the drive refuses is left out) and
P0952 the number of faults (whether it counts every fault or those held was not found:
either is read right here; were it to count trips, a trip's second fault would be found
only at its acknowledgement).

A trip is two entries, one per fault number: each is a fault of its own (the document's
F1 and F2), both with the trip's one time. Newest first: the recent trip, its second
fault before its first, then trip -1, and so on. A fault number of 0 is no fault (the
SED2 document resets [0]/[1] to 0 at an acknowledgement). Whether a trip's second fault
stamps the trip again is not documented: were it so, its first fault, read before the
second came, would be kept a second time with the later time.

What is watched, and read again after a sweep (a change meanwhile: read it again): P0952,
which a new fault moves, and r0948[4], the low word of trip -1's seconds, which moves
with each acknowledgement (r0948's words go down with r0947's pairs: its indexes are
named by trip, "Recent fault trip -1"): a trip that came and was acknowledged between two watches is
noticed even where P0952 counts only the faults held (and reads the same before and
after), so long as the two trips' seconds differ in their low word. r0947[0] would add
nothing these two do not show, for a third telegram every watch.

Times are in the run time counter's base, to the second (Runtime of seconds x 1000),
read in the same sweep: an entry's age is the counter now minus its time. The counter
stands still while the drive is off and goes on from there at power-up: the age is the
time the drive was powered since the entry, exact while it stayed powered; a power cycle
between the two makes the entry look younger by the time the drive was off (the
watcher's rule for a drive seen off since its last sweep,
:mod:`pkwbus.service.history.watch`).
"""

from __future__ import annotations

from dataclasses import dataclass

from pkwbus.protocol.logs.model import (
    Kind,
    LogEntry,
    Opaque,
    Read,
    Runtime,
    SweepResult,
    TimeBase,
    Values,
)

__all__ = [
    "CLOCK",
    "FAULTS",
    "MICROMASTER_FAULT_BUFFER",
    "RUNTIME",
    "TRIPS",
    "WATCHED",
    "FaultBuffer",
    "seconds_of",
]

TRIPS = 4
FAULTS = 2 * TRIPS  # r0947[8]
WORDS = 3  # r0948: three words per trip

COUNT = Read(952)  # P0952 number of faults
WATCHED = (COUNT, Read(948, 4))  # and r0948[4], trip -1's seconds, low word
RUNTIME = (Read(2114, 0), Read(2114, 1))  # r2114 seconds: [0] high word, [1] low word
CLOCK = tuple(Read(2115, i) for i in range(WORDS))  # P2115 AOP real-time clock


def _number(i: int) -> Read:
    return Read(947, i)  # r0947 fault number


def _value(i: int) -> Read:
    return Read(949, i)  # r0949 fault value


def _time(trip: int) -> tuple[Read, ...]:
    return tuple(Read(948, WORDS * trip + w) for w in range(WORDS))  # r0948 fault time


def seconds_of(high: int | None, low: int | None) -> int | None:
    """The seconds of two words, high and low (None where the drive refused either)."""
    return None if high is None or low is None else (high << 16) + low


class _Sweep:
    """The watched values, the run time counter, P2115 and every fault number; then the
    time of each trip there and the value of each fault; then the watched values again."""

    def __init__(self) -> None:
        self.known: dict[Read, int | None] = {}
        self.before: tuple[int | None, ...] | None = None
        self.after: tuple[int | None, ...] | None = None
        self._round = 0

    def next(self) -> tuple[Read, ...]:
        if self._round == 0:
            return (*WATCHED, *RUNTIME, *CLOCK, *(_number(i) for i in range(FAULTS)))
        if self._round == 1:
            present = self._present()
            trips = sorted({i // 2 for i in present})
            return (*(r for t in trips for r in _time(t)), *(_value(i) for i in present))
        if self._round == 2:
            return WATCHED
        return ()

    def feed(self, values: Values) -> None:
        if self._round == 0:
            self.before = tuple(values.get(r) for r in WATCHED)
        if self._round == 2:
            self.after = tuple(values.get(r) for r in WATCHED)
        else:
            self.known.update(values)
        self._round += 1
        if self._round == 1 and not self._present():
            self._round = 2  # an empty buffer: no times or values to read

    def _present(self) -> list[int]:
        return [i for i in range(FAULTS) if self.known.get(_number(i))]

    def result(self) -> SweepResult | None:
        known = self.known
        if self._round < 3 or any(known.get(_number(i)) is None for i in range(FAULTS)):
            return None  # not over, or its fault numbers refused
        if self.before != self.after:
            return None  # the buffer changed while it was read
        seconds = seconds_of(*(known.get(r) for r in RUNTIME))
        runtime = Runtime(seconds * 1000) if seconds is not None else None
        clock = any(known.get(r) for r in CLOCK)  # refused: a drive without the AOP clock
        entries = []
        for trip in range(TRIPS):
            when = self._when(trip, clock)
            for i in (2 * trip + 1, 2 * trip):  # its second fault, then its first
                code = known[_number(i)]
                if code:
                    entries.append(LogEntry(Kind.FAULT, code, known.get(_value(i)), when))
        return SweepResult(tuple(entries), runtime)

    def _when(self, trip: int, clock: bool) -> Runtime | Opaque | None:
        high, low, third = (self.known.get(r) for r in _time(trip))
        if high is None or low is None or third is None:
            return None
        if clock or third:
            return Opaque((high << 32) + (low << 16) + third)  # not r2114's layout
        return Runtime(((high << 16) + low) * 1000)


@dataclass(frozen=True, slots=True)
class FaultBuffer:
    """The MICROMASTER 4 fault buffer as a :class:`~pkwbus.protocol.logs.model.DriveLog`."""

    name: str = "MICROMASTER 4 fault buffer"
    time_base: TimeBase = TimeBase.RUNTIME
    runtime: tuple[Read, ...] = RUNTIME
    kinds: tuple[Kind, ...] = (Kind.FAULT,)

    def watch(self) -> tuple[Read, ...]:
        return WATCHED

    def sweep(self, previous: SweepResult | None = None) -> _Sweep:
        return _Sweep()  # read whole each time: eight faults of four trips


MICROMASTER_FAULT_BUFFER = FaultBuffer()
