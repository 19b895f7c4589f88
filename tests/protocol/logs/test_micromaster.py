"""The MICROMASTER 4 fault buffer as its documents word it, kept here by the test: r0947
two fault numbers a trip, the recent trip at [0]/[1], each pair moved down by an
acknowledgement and [0]/[1] then 0 (SED2 Operating Instructions p. 85, a drive of the
MICROMASTER 4 parameter set); r0948 three words a trip, the run time counter's seconds,
high word, low word and 0, or P2115's words where that is set (MICROMASTER 440 Parameter
List 01/06, r0948); r2114 the counter, seconds = [0] x 65536 + [1] (the same list, r2114).
What the documents leave open is left out of the runs (a third fault in one trip, an
acknowledgement with none active, whether a second fault stamps its trip again) or kept
both ways (P0952 counting every fault, or those held). The reader must find each trip's
faults once, with the trip's time to within the counter's second."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol.logs import MICROMASTER_FAULT_BUFFER, Kind, LogEntry, Opaque, Read, Runtime
from pkwbus.protocol.logs.micromaster import CLOCK, WATCHED
from tests.protocol.logs.test_logs import sweep

LOG = MICROMASTER_FAULT_BUFFER


@dataclass
class Mm4Buffer:
    """The buffer as the documents word it. ``now``: the drive's run time counter, in
    seconds (r2114 shows its whole seconds); ``held``: P0952 reads the faults held, not
    every fault entered."""

    held: bool = False
    now: float = 0.0
    numbers: list[int] = field(default_factory=lambda: [0] * 8)
    values: list[int] = field(default_factory=lambda: [0] * 8)
    times: list[int] = field(default_factory=lambda: [0] * 12)
    clock: list[int] = field(default_factory=lambda: [0] * 3)
    entered: int = 0
    refused: frozenset[int] = frozenset()  # parameters the drive refuses

    def fault(self, number: int, value: int) -> bool:
        """A fault comes: the recent trip's first, or its second; False for a third (what
        a third does is not documented: the runs make none)."""
        if not self.numbers[0]:
            self.numbers[0], self.values[0] = number, value
            seconds = math.floor(self.now)
            words = [seconds >> 16 & 0xFFFF, seconds & 0xFFFF, 0]
            self.times[0:3] = self.clock if any(self.clock) else words
        elif not self.numbers[1]:
            self.numbers[1], self.values[1] = number, value
        else:
            return False
        self.entered += 1
        return True

    def acknowledge(self) -> bool:
        """Each pair moves down a pair, the oldest dropped, [0]/[1] then 0; False with no
        active fault (not documented: the runs make none)."""
        if not self.numbers[0]:
            return False
        for column, width in ((self.numbers, 2), (self.values, 2), (self.times, 3)):
            column[width:] = column[:-width]
            column[:width] = [0] * width
        return True

    def __call__(self, read: Read) -> int | None:
        i, pnu = read.index, read.pnu
        if pnu in self.refused:
            return None
        if pnu == 952:
            return sum(1 for n in self.numbers if n) if self.held else self.entered & 0xFFFF
        if pnu == 2114:
            seconds = math.floor(self.now)
            return seconds >> 16 & 0xFFFF if i == 0 else seconds & 0xFFFF
        columns = {947: self.numbers, 949: self.values, 948: self.times, 2115: self.clock}
        return columns[pnu][i] if pnu in columns else None


def at(seconds: int) -> Runtime:
    return Runtime(seconds * 1000)


def test_the_recent_trip_first_and_in_a_trip_its_second_fault_first() -> None:
    buffer = Mm4Buffer(now=70_000.4)  # past 65,536 s: the high word counts
    buffer.fault(3, 12)
    buffer.fault(4, 13)
    buffer.acknowledge()
    buffer.now = 70_100.9
    buffer.fault(7, 5)
    buffer.now = 70_200.0
    found = sweep(LOG, buffer)
    assert found is not None and found.runtime == at(70_200)
    assert found.entries == (
        LogEntry(Kind.FAULT, 7, 5, at(70_100)),
        LogEntry(Kind.FAULT, 4, 13, at(70_000)),  # the trip's one time, for both faults
        LogEntry(Kind.FAULT, 3, 12, at(70_000)),
    )
    assert buffer.numbers == [7, 0, 3, 4, 0, 0, 0, 0]
    assert buffer.times[3:6] == [1, 70_000 - 65_536, 0]


def test_an_acknowledgement_moves_the_pairs_and_the_fourth_trip_back_is_dropped() -> None:
    buffer = Mm4Buffer()
    for code in range(1, 6):
        buffer.now += 10
        buffer.fault(code, 0)
        buffer.acknowledge()
    found = sweep(LOG, buffer)
    assert found is not None
    assert [e.code for e in found.entries] == [5, 4, 3]  # [0]/[1] empty, 1 and 2 dropped
    assert buffer.numbers[:2] == [0, 0]


def test_where_the_aop_clock_is_set_the_times_are_opaque() -> None:
    buffer = Mm4Buffer(now=100.0)
    buffer.clock = [2026, 517, 930]  # whatever P2115 holds: its encoding is not known
    buffer.fault(3, 1)
    found = sweep(LOG, buffer)
    assert found is not None
    (entry,) = found.entries
    assert entry.drive_time == Opaque((2026 << 32) + (517 << 16) + 930)


def test_a_third_word_other_than_0_is_not_the_counters_layout() -> None:
    buffer = Mm4Buffer(now=100.0)
    buffer.fault(3, 1)
    buffer.times[2] = 9
    found = sweep(LOG, buffer)
    assert found is not None and found.entries[0].drive_time == Opaque((100 << 16) + 9)


def test_refused_values_and_a_drive_without_the_clock() -> None:
    """r0949's size is not documented: a value refused is left out. P2115 refused: an
    inverter without the AOP clock feature (the list, P2115): the counter's times."""
    buffer = Mm4Buffer(now=50.0, refused=frozenset({949, 2115}))
    buffer.fault(3, 1)
    found = sweep(LOG, buffer)
    assert found is not None and found.entries == (LogEntry(Kind.FAULT, 3, None, at(50)),)


def test_refused_fault_numbers_or_a_change_while_it_is_read_read_nothing() -> None:
    assert sweep(LOG, Mm4Buffer(refused=frozenset({947}))) is None
    buffer = Mm4Buffer()
    buffer.fault(3, 1)

    def second_fault_after_round(n: int) -> None:
        if n == 0:  # after the fault numbers were read
            buffer.fault(4, 2)

    assert sweep(LOG, buffer, second_fault_after_round) is None
    found = sweep(LOG, buffer)
    assert found is not None and [e.code for e in found.entries] == [4, 3]


def test_the_watch_and_an_empty_buffers_sweep() -> None:
    assert LOG.watch() == (Read(952), Read(948, 4)) == WATCHED
    s = LOG.sweep()
    reads = 0
    while batch := s.next():
        reads += len(batch)
        s.feed({r: Mm4Buffer()(r) for r in batch})
    assert reads == 2 + 2 + len(CLOCK) + 8 + 2
    result = s.result()
    assert result is not None and result.entries == ()


Step = tuple[str, float]
STEPS = st.lists(
    st.tuples(st.sampled_from(["fault", "fault", "acknowledge", "watch"]), st.floats(0, 3000)),
    max_size=60,
)


def run(buffer: Mm4Buffer, steps: list[Step]) -> None:
    """The run against the reader, read as the watcher reads it: the watched values every
    ``watch`` step and at the end, a sweep when they changed. Each fault held at a watch
    is found once, with its trip's time within the counter's second."""
    came: dict[int, float] = {}  # fault number -> its trip's time (the drive's seconds)
    found: dict[LogEntry, float] = {}  # entry -> its time as placed, when first found
    held: set[int] = set()
    last: tuple[int | None, ...] | None = None
    code = 0
    for kind, dt in [*steps, ("watch", 0.0)]:
        buffer.now += dt
        if kind == "fault":
            code += 1
            if buffer.fault(code, code % 5):
                came[code] = came.get(buffer.numbers[0], buffer.now)
        elif kind == "acknowledge":
            buffer.acknowledge()
        else:
            held |= {n for n in buffer.numbers if n}
            now = tuple(buffer(r) for r in LOG.watch())
            if now == last:
                continue
            last, result = now, sweep(LOG, buffer)
            assert result is not None and result.runtime is not None
            for e in result.entries:
                assert isinstance(e.drive_time, Runtime)
                placed = buffer.now - (result.runtime.ms - e.drive_time.ms) / 1000
                found.setdefault(e, placed)
    assert sorted(e.code for e in found) == sorted(held)  # each once, none made up
    for e, placed in found.items():
        assert abs(placed - came[e.code]) < 1.0


@settings(max_examples=300)
@given(STEPS, st.integers(0, 2**32 - 10**6))
def test_any_run_where_p0952_counts_every_fault_finds_each_trip_once(
    steps: list[Step], start: int
) -> None:
    run(Mm4Buffer(now=float(start)), steps)


@settings(max_examples=300)
@given(
    STEPS.map(lambda s: [(k, 1.0 + dt if k == "fault" else dt) for k, dt in s]),
    st.sampled_from([0, 65_536 - 500]),  # the high word's turn, too
)
def test_any_run_where_p0952_counts_the_faults_held_finds_each_trip_once(
    steps: list[Step], start: int
) -> None:
    """P0952 then reads the same after a trip came and was acknowledged: r0948[4], trip
    -1's time, shows it, so long as the two trips' seconds differ in their low word (here
    a second or more apart, and less than 65,536 s: two trips in one second, acknowledged
    between two watches, look the same to the watch until the next change)."""
    if sum(dt for _, dt in steps) < 65_000:
        run(Mm4Buffer(held=True, now=float(start)), steps)
