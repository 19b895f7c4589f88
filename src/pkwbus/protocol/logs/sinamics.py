"""The SINAMICS fault buffer, read over USS: eight fault cases of eight faults.

SINAMICS S200 Operating Instructions 11/2023 (FW V6.3), appendix A.3 "Fault
buffer": 64 entries, 8 fault cases x 8 faults. Index [0..7] is the active
fault case (faults 1..8 in the order they came), [8..15] the 1st
acknowledged case, ..., [56..63] the 7th. On acknowledgement the cases move
down by one and the last is dropped; beyond 8 active faults only the entry
at the eighth place is overwritten. r0947 fault number (Unsigned16), r0949
fault value ("as integer number"), r0948 fault time received in ms and
r2130 in days. The buffer's change counter r0944 is read before and after
the sweep (the PROFIdrive rule of P944: "incremented each time that the
fault buffer changes"): a change meanwhile means the sweep is read again.

Times are in the drive's runtime base, r2114 ("System runtime = r2114[1] x
days + r2114[0] x milliseconds"; it counts only while the control unit is
powered; SINAMICS CU240D-2 Operating Instructions 04/2018, section 8.2):
r2114 is read in the same sweep, so an entry's age is the runtime now minus
its time, exact while the drive stayed powered since. What an unused entry
reads is not stated; a fault number of 0 is taken as none (the SED2
Operating Instructions reset acknowledged entries to 0).
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

__all__ = [
    "CASES",
    "FAULTS_PER_CASE",
    "RUNTIME_DAYS",
    "RUNTIME_MS",
    "SINAMICS_FAULT_BUFFER",
    "FaultBuffer",
]

CASES = 8
FAULTS_PER_CASE = 8
ENTRIES = CASES * FAULTS_PER_CASE

COUNTER = Read(944)  # r0944 counter of fault buffer changes
RUNTIME_MS = Read(2114, 0)  # r2114[0] system runtime, ms
RUNTIME_DAYS = Read(2114, 1)  # r2114[1] system runtime, days


def _number(i: int) -> Read:
    return Read(947, i)  # r0947 fault number


def _details(i: int) -> tuple[Read, Read, Read]:
    # r0949 fault value, r0948 fault time received (ms), r2130 fault time received (days)
    return Read(949, i, signed=True), Read(948, i), Read(2130, i)


class _Sweep:
    """Counter, runtime and every fault number; then the details of each fault there;
    then the counter again."""

    def __init__(self) -> None:
        self.known: dict[Read, int | None] = {}
        self.counter_after: int | None = None
        self._round = 0

    def next(self) -> tuple[Read, ...]:
        if self._round == 0:
            return (COUNTER, RUNTIME_MS, RUNTIME_DAYS, *(_number(i) for i in range(ENTRIES)))
        if self._round == 1:
            return tuple(r for i in self._present() for r in _details(i))
        if self._round == 2:
            return (COUNTER,)
        return ()

    def feed(self, values: Values) -> None:
        if self._round == 2:
            self.counter_after = values.get(COUNTER)
        else:
            self.known.update(values)
        self._round += 1
        if self._round == 1 and not self._present():
            self._round = 2  # an empty buffer: no details to read

    def _present(self) -> list[int]:
        return [i for i in range(ENTRIES) if self.known.get(_number(i))]

    def result(self) -> SweepResult | None:
        known = self.known
        if self._round < 3 or any(known.get(_number(i)) is None for i in range(ENTRIES)):
            return None  # not over, or its fault numbers refused
        before = known.get(COUNTER)
        if before is None or before != self.counter_after:
            return None  # the buffer changed while it was read
        ms, days = known.get(RUNTIME_MS), known.get(RUNTIME_DAYS)
        runtime = Runtime.read(days, ms)
        entries = []
        for case in range(CASES):  # the newest case first; in a case, the latest fault first
            for place in reversed(range(FAULTS_PER_CASE)):
                i = case * FAULTS_PER_CASE + place
                code = known[_number(i)]
                if not code:
                    continue
                value_read, ms_read, days_read = _details(i)
                when = Runtime.read(known.get(days_read), known.get(ms_read))
                entries.append(LogEntry(Kind.FAULT, code, known.get(value_read), when))
        return SweepResult(tuple(entries), runtime)


@dataclass(frozen=True, slots=True)
class FaultBuffer:
    """The SINAMICS fault buffer as a :class:`~pkwbus.protocol.logs.model.DriveLog`."""

    name: str = "SINAMICS fault buffer"
    time_base: TimeBase = TimeBase.RUNTIME
    runtime: tuple[Read, ...] = (RUNTIME_MS, RUNTIME_DAYS)
    kinds: tuple[Kind, ...] = (Kind.FAULT,)

    def watch(self) -> tuple[Read, ...]:
        return (COUNTER,)

    def sweep(self, previous: SweepResult | None = None) -> _Sweep:
        return _Sweep()  # read whole each time: faults are rare, a change costs one sweep


SINAMICS_FAULT_BUFFER = FaultBuffer()
