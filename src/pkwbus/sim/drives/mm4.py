"""The fault buffer a simulated MICROMASTER 4 drive keeps, laid out as its documents lay it
out. Pure: the drive model passes the run time counter's seconds.

r0947[8] fault numbers, two per trip: [0]/[1] the recent trip (the first and the second
active fault), [2]/[3] trip -1, ..., [6]/[7] trip -3; an acknowledgement moves each pair
down to the next pair and resets [0]/[1] to 0 (SED2 Operating Instructions, "Reading
Faults", p. 85: the SED2 has the MICROMASTER 4 parameter set). r0948[12] three words per
trip, [0..2] the recent trip, [3..5] trip -1, ...: from r2114 the seconds' high word, low
word and 0; where P2115 (the AOP real-time clock) is not 0, P2115[0..2] instead
(MICROMASTER 440 Parameter List 6SE6400-5BB00-0BP0, 01/06, r0948). r2114[2] the run time
counter, seconds = [0] x 65536 + [1], counted while the drive is powered and kept over a
power cycle (the same list, r2114): the model's ``powered_ms``.

The simulator's choices, where the documents say nothing: a third fault while two are
active overwrites [1]; a trip's time is its first fault's (the second leaves it); the
clock's words are taken as they are at the trip (the simulator does not know their
encoding, and does not advance them); acknowledging with no active fault changes
nothing. r0949 (fault values, whose size is not documented) is kept beside r0947, eight
words, a value's low 16 bits. P0952 (the number of faults) counts every fault entered,
Unsigned16: whether the drive counts those or the faults held is not documented. An
empty place reads 0 everywhere.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Final

__all__ = ["FIELDS", "TRIPS", "Mm4FaultBuffer", "Mm4Trip", "counter_words"]

TRIPS = 4
PER_TRIP = 2
WORDS = 3
_WORD = 0xFFFF

Words = tuple[int, int, int]


def counter_words(seconds: int) -> tuple[int, int]:
    """Seconds as r2114 shows them: (high word, low word)."""
    return seconds >> 16 & _WORD, seconds & _WORD


@dataclass(frozen=True, slots=True)
class Mm4Trip:
    """One trip: its faults (number, value), the first first; its three time words."""

    faults: tuple[tuple[int, int], ...]
    stamp: Words


def _no_clock() -> Words:
    return (0, 0, 0)


class Mm4FaultBuffer:
    """``trips[0]`` the recent trip, ``trips[k]`` trip -k (None: an empty pair); ``count``
    P0952; ``clock`` the AOP clock's words now (P2115; all 0: not set)."""

    def __init__(self, clock: Callable[[], Words] = _no_clock) -> None:
        self.trips: list[Mm4Trip | None] = [None] * TRIPS
        self.count = 0
        self.clock = clock

    def enter(self, number: int, value: int, seconds: int) -> None:
        """A fault comes, at ``seconds`` of the run time counter."""
        fault = (number & _WORD, value & _WORD)
        recent = self.trips[0]
        if recent is None:
            clock = tuple(w & _WORD for w in self.clock())
            stamp: Words = (clock[0], clock[1], clock[2]) if any(clock) else (
                *counter_words(seconds), 0
            )  # fmt: skip
            self.trips[0] = Mm4Trip((fault,), stamp)
        else:
            kept = recent.faults[: PER_TRIP - 1]  # beyond two: the second place overwritten
            self.trips[0] = replace(recent, faults=(*kept, fault))
        self.count = (self.count + 1) & _WORD

    def acknowledge(self) -> bool:
        """The recent trip moves down a pair, the oldest is dropped; False (nothing changes)
        with no active fault."""
        if self.trips[0] is None:
            return False
        self.trips = [None, *self.trips[:-1]]
        return True

    def read(self, name: str, index: int) -> int:
        """Parameter ``name`` (a key of :data:`FIELDS`) at ``index``; 0 when empty."""
        if name == "mm4_fault_count":
            return self.count
        if name == "mm4_fault_time":
            trip = self.trips[index // WORDS] if index < TRIPS * WORDS else None
            return 0 if trip is None else trip.stamp[index % WORDS]
        trip = self.trips[index // PER_TRIP] if index < TRIPS * PER_TRIP else None
        place = index % PER_TRIP
        if trip is None or place >= len(trip.faults):
            return 0
        return trip.faults[place][name == "mm4_fault_value"]


# The ``live`` names of the buffer's parameters (table.py).
FIELDS: Final = frozenset({"mm4_fault_number", "mm4_fault_value", "mm4_fault_time",
                           "mm4_fault_count"})  # fmt: skip
