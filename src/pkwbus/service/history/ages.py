"""Entries a drive times by their age (:class:`~pkwbus.protocol.logs.Age`: a PROFIdrive
P948 of Unsigned16, "seconds since the last fault occurred", ABB RPBA-01): placed on the
wall clock, and each known again at every sweep.

An age grows with every read, so it cannot tell an entry apart as a runtime time does.
An aged entry's time is when the drive answered the read of its age, minus the age; read
again, the same entry places within a second or two of that (the age counts whole
seconds, an answer takes its time, the drive's clock runs against ours). So an aged entry
is known by its kind, code and value and the second it was first placed at (its key);
an entry of a sweep is a kept one of the same kind, code and value placed within
:data:`AGE_SLACK` plus :data:`AGE_DRIFT` of its age, each kept entry met by one entry of
a sweep at most (two alike in the buffer are two entries), alike ones in the order they
came: the oldest of a sweep meets the oldest kept one within its slack. Alike entries
placed within their slack of each other cannot be told apart: where the oldest of them
has left the buffer between two sweeps, the next is taken for it, and one of them is
kept once too few.

The documents do not say what an age does while the drive is off, nor at the top of its
number (65,535 s of an Unsigned16, about 18 h). An age at the top may have stopped there:
its entry is taken for the latest alike one kept placed before it (the newest of a sweep
first), and one with none is kept without a time (``seen``). An age that stood still
while the drive was off places its entry later after that, by the time the drive was
off, and one that went back to 0 at the top places it anew: either way the entry is kept
again, as another one.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace

from pkwbus.protocol.logs import Age, LogEntry, Read
from pkwbus.service.history.store import DriveEvent

__all__ = ["AGE_DRIFT", "AGE_SLACK", "AgedKeys"]

AGE_SLACK = 2.0  # seconds: the whole seconds an age counts, and the time an answer takes
AGE_DRIFT = 0.0002  # of the age: the drive's clock against ours (200 ppm)
_PLACED, _TOP = "age:", "age-top:"  # an aged key's mark: placed there, or at least that old


class AgedKeys:
    """The aged entries kept of one drive: by kind, code and value (the key's head), where
    each was placed."""

    def __init__(self, keys: Iterable[str]) -> None:
        self._kept: dict[str, list[tuple[float, int, str]]] = {}
        self._keys: set[str] = set()
        for key in keys:
            self._add(key)

    def _add(self, key: str) -> None:
        head, _, tail = key.rpartition("|")
        mark = _TOP if tail.startswith(_TOP) else _PLACED if tail.startswith(_PLACED) else ""
        if not mark:
            return  # not an aged entry's key
        placed, _, n = tail[len(mark) :].partition("~")
        try:
            kept = (float(placed), int(n or 1), key)
        except ValueError:
            return
        self._kept.setdefault(head + "|", []).append(kept)
        self._keys.add(key)

    def place(
        self,
        entries: Sequence[LogEntry],
        events: Sequence[DriveEvent],
        answered: Mapping[Read, float],
    ) -> list[DriveEvent]:
        """``events`` (one per entry of a sweep), each aged one with its time and its key:
        a kept entry's where it is that one. ``answered``: when each read was answered."""
        out = list(events)
        groups: dict[str, list[tuple[float, int, Age]]] = {}
        for i, entry in enumerate(entries):
            age = entry.drive_time
            if isinstance(age, Age):
                at = answered.get(age.read, events[i].seen)
                groups.setdefault(events[i].key, []).append((at - age.seconds, -i, age))
        for head, aged in groups.items():
            aged.sort()  # the oldest first; placed alike, the one further down the buffer
            met = _meet(aged, sorted(self._kept.get(head, [])))
            for placed, minus_i, age in aged:  # in time order: a new key's number follows it
                top = age.seconds >= age.top
                key = met.get(-minus_i) or self._new(head, _TOP if top else _PLACED, placed)
                when, source = (None, "seen") if top else (placed, "runtime")
                out[-minus_i] = replace(out[-minus_i], key=key, time=when, time_source=source)
        return out

    def _new(self, head: str, mark: str, placed: float) -> str:
        key = base = f"{head}{mark}{round(placed)}"
        n = 1
        while key in self._keys:  # two alike placed in the same second
            n += 1
            key = f"{base}~{n}"
        self._add(key)
        return key


def _meet(
    aged: Sequence[tuple[float, int, Age]], kept: Sequence[tuple[float, int, str]]
) -> dict[int, str]:
    """Which of ``aged`` (in time order) are which of ``kept`` (in the order they were
    placed): each in turn the first kept one after the last met that places within its
    slack, so that alike entries keep their order; then each one at the top of its age,
    the newest first, the latest kept one placed before it that is left."""
    met: dict[int, str] = {}
    start = 0
    for placed, minus_i, age in aged:
        if age.seconds >= age.top:
            continue
        slack = AGE_SLACK + AGE_DRIFT * age.seconds
        for j in range(start, len(kept)):
            when, _, key = kept[j]
            if when > placed + slack:
                break
            if when >= placed - slack:
                met[-minus_i], start = key, j + 1
                break
    left = [k for k in kept if k[2] not in met.values()]
    for placed, minus_i, age in reversed(aged):
        if age.seconds < age.top:
            continue
        slack = AGE_SLACK + AGE_DRIFT * age.seconds
        found = next((k for k in reversed(left) if k[0] <= placed + slack), None)
        if found is not None:
            met[-minus_i] = found[2]
            left.remove(found)
    return met
