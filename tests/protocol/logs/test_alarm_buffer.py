"""The SINAMICS alarm buffer as its documents lay it out: eight places [0..7], the oldest
at [0] and the latest at [7], [7] overwritten when eight alarms are active (G120C
Operating Instructions 09/2017, section 8.3); the history [8..63], the latest at [8] and
the oldest dropped beyond [63] (G120 parameter descriptions, r2122); a gone alarm moved
there at once (G220 Operating Instructions 04/2024, section 15.6) or, once the eight are
full and another comes, all gone ones together (ET 200pro FC-2 Operating Instructions
09/2017, section 10.4); r2121 counting every change. Both ways are kept here, by the
test, as the documents word them; the reader must find the same under each."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol.logs import SINAMICS_ALARM_BUFFER, Kind, LogEntry, Read, Runtime, SweepResult
from pkwbus.protocol.logs.model import MS_PER_DAY
from tests.protocol.logs.test_logs import sweep as logs_sweep


@dataclass(frozen=True)
class Alarm:
    code: int
    value: int
    received: Runtime
    removed: Runtime | None = None


class AlarmBuffer:
    """The alarm buffer kept as the documents word it; ``at_once``: a gone alarm goes
    into the history at once (G220), else only when the eight places are full (ET 200pro)."""

    def __init__(self, *, at_once: bool) -> None:
        self.at_once = at_once
        self.places: list[Alarm] = []  # [0] the oldest
        self.history: list[Alarm] = []  # [0] is r2122[8], the latest
        self.counter = 0
        self.runtime = Runtime(0)
        self.reads = 0
        self.dropped: set[LogEntry] = set()  # what the buffer itself lost: overwritten, too old

    def come(self, code: int, value: int) -> None:
        self.runtime = Runtime(self.runtime.ms + 1000)
        alarm = Alarm(code, value, self.runtime)
        if len(self.places) == 8 and not self.at_once:
            gone = [a for a in self.places if a.removed is not None]
            self._to_history(gone)
            self.places = [a for a in self.places if a.removed is None]
        if len(self.places) == 8:
            self.dropped.add(_entry(self.places[7]))
            self.places[7] = alarm  # eight active: [7] overwritten
        else:
            self.places.append(alarm)
        self.counter = (self.counter + 1) % 65536

    def go(self, which: int) -> None:
        """The active alarm ``which`` (0: the oldest active one) goes."""
        active = [i for i, a in enumerate(self.places) if a.removed is None]
        if not active:
            return
        self.runtime = Runtime(self.runtime.ms + 1000)
        i = active[which % len(active)]
        gone = replace(self.places[i], removed=self.runtime)
        if self.at_once:
            del self.places[i]
            self._to_history([gone])
        else:
            self.places[i] = gone
        self.counter = (self.counter + 1) % 65536

    def _to_history(self, alarms: list[Alarm]) -> None:
        latest_first = sorted(alarms, key=lambda a: a.received.ms, reverse=True)
        history = latest_first + self.history
        self.dropped |= {_entry(a) for a in history[56:]}
        self.history = history[:56]

    def held(self) -> set[LogEntry]:
        return {_entry(a) for a in self.places + self.history}

    def __call__(self, read: Read) -> int | None:
        self.reads += 1
        i = read.index
        if read.pnu == 2121:
            return self.counter
        if read.pnu == 2114:
            days, ms = divmod(self.runtime.ms, MS_PER_DAY)
            return ms if i == 0 else days
        alarm = self.places[i] if i < len(self.places) else None
        if i >= 8:
            alarm = self.history[i - 8] if i - 8 < len(self.history) else None
        if alarm is None:
            return 0 if read.pnu in (2122, 2123, 2124, 2145) else None
        days, ms = divmod(alarm.received.ms, MS_PER_DAY)
        fields = {2122: alarm.code, 2124: alarm.value, 2123: ms, 2145: days}
        return fields.get(read.pnu)


def _entry(alarm: Alarm) -> LogEntry:
    return LogEntry(Kind.ALARM, alarm.code, alarm.value, alarm.received)


def sweep(
    buffer: Callable[[Read], int | None],
    previous: SweepResult | None = None,
    between: Callable[[int], None] = lambda _: None,
) -> SweepResult | None:
    return logs_sweep(SINAMICS_ALARM_BUFFER, buffer, between, previous)


@pytest.mark.parametrize("at_once", [True, False])
def test_the_eight_places_latest_first_then_the_history_latest_first(at_once: bool) -> None:
    buffer = AlarmBuffer(at_once=at_once)
    buffer.come(7409, 5)
    buffer.come(30030, -2)
    buffer.go(0)  # A07409 goes
    buffer.come(7891, 1)
    found = sweep(buffer)
    assert found is not None and found.runtime == buffer.runtime
    codes = [e.code for e in found.entries]
    # G220: A07409 is in the history; ET 200pro: it stays at [0], gone, until eight are full.
    assert codes == [7891, 30030, 7409]
    assert found.entries[2] == LogEntry(Kind.ALARM, 7409, 5, Runtime(1000))
    assert found.places == ((1, 0, 8) if at_once else (2, 1, 0))


def test_eight_active_alarms_and_another_overwrite_the_eighth_place() -> None:
    buffer = AlarmBuffer(at_once=True)
    for n in range(10):
        buffer.come(7900 + n, n)
    found = sweep(buffer)
    assert found is not None
    assert [e.code for e in found.entries] == [7909, 7906, 7905, 7904, 7903, 7902, 7901, 7900]


@pytest.mark.parametrize("at_once", [True, False])
def test_an_alarm_that_came_and_went_between_two_sweeps_is_found(at_once: bool) -> None:
    buffer = AlarmBuffer(at_once=at_once)
    for n in range(60):  # a full history
        buffer.come(7000 + n, n)
        buffer.go(0)
    first = sweep(buffer)
    assert first is not None and set(first.entries) == buffer.held()
    buffer.come(7409, 77)
    buffer.go(0)
    again = sweep(buffer, first)
    assert again is not None
    assert LogEntry(Kind.ALARM, 7409, 77, Runtime(121_000)) in again.entries
    assert set(again.entries) == buffer.held()
    assert again == sweep(buffer)  # the same as a whole sweep, places and all


def test_after_a_first_sweep_only_what_came_since_is_read() -> None:
    """A full history is read whole once; then a new gone alarm costs the eight places, the
    history down to the last sweep's newest, the runtime and the counter twice."""
    buffer = AlarmBuffer(at_once=True)
    for n in range(60):
        buffer.come(7000 + n, n)
        buffer.go(0)
    buffer.reads = 0
    first = sweep(buffer)
    assert buffer.reads == 1 + 2 + 64 + 3 * 56 + 1
    buffer.come(7409, 77)
    buffer.go(0)
    buffer.reads = 0
    assert sweep(buffer, first) is not None
    # counter, runtime, 8 codes; [8] (new) and [9] (the mark) whole; the counter again
    assert buffer.reads == 1 + 2 + 8 + 4 + 4 + 1


def test_a_change_while_the_buffer_is_read_means_read_again() -> None:
    buffer = AlarmBuffer(at_once=True)
    buffer.come(7409, 1)
    first = sweep(buffer)

    def comes_after_round(n: int) -> None:
        if n == 0:
            buffer.come(7891, 2)

    assert sweep(buffer, first, comes_after_round) is None
    found = sweep(buffer, first)
    assert found is not None and [e.code for e in found.entries] == [7891, 7409]


def test_a_refused_code_in_the_history_fails_the_sweep() -> None:
    buffer = AlarmBuffer(at_once=True)
    buffer.come(7409, 1)
    buffer.go(0)
    first = sweep(buffer)
    buffer.come(7891, 2)
    buffer.go(0)

    def refusing(read: Read) -> int | None:
        return None if (read.pnu, read.index) == (2122, 9) else buffer(read)

    assert sweep(refusing, first) is None


def test_a_newest_entry_whose_time_was_refused_is_no_mark() -> None:
    """A drive that refuses r2145: entries differ only by code and value, so the same alarm
    again could pass for the last sweep's newest; the history is read to its end instead."""
    buffer = AlarmBuffer(at_once=True)

    def no_days(read: Read) -> int | None:
        return None if read.pnu == 2145 else buffer(read)

    buffer.come(7001, 1)
    buffer.go(0)
    first = sweep(no_days)
    buffer.come(7002, 2)
    buffer.go(0)
    buffer.come(7001, 1)
    buffer.go(0)
    found = sweep(no_days, first)
    assert found is not None and [e.code for e in found.entries] == [7001, 7002, 7001]
    assert found == sweep(no_days)


def test_a_cleared_history_is_read_down_to_its_end() -> None:
    """The mark is not met (the history was cleared meanwhile): everything there is read,
    nothing of the last sweep is carried."""
    buffer = AlarmBuffer(at_once=True)
    for n in range(5):
        buffer.come(7000 + n, n)
        buffer.go(0)
    first = sweep(buffer)
    buffer.history = []
    buffer.come(7409, 1)
    buffer.go(0)
    buffer.counter += 1
    found = sweep(buffer, first)
    assert found is not None and found.entries == (LogEntry(Kind.ALARM, 7409, 1, Runtime(11_000)),)


Step = tuple[str, int]
steps = st.lists(
    st.one_of(
        st.tuples(st.just("come"), st.integers(1, 4)),
        st.tuples(st.just("go"), st.integers(0, 7)),
        st.tuples(st.just("sweep"), st.just(0)),
    ),
    max_size=120,
)


@settings(max_examples=300)
@given(at_once=st.booleans(), script=steps)
def test_every_alarm_is_found_and_a_sweep_reads_what_a_whole_one_does(
    at_once: bool, script: list[Step]
) -> None:
    """Any run of alarms coming and going with sweeps between: each sweep after the first,
    reading only what came since, gives what a whole sweep gives, which is what the buffer
    holds; so every alarm that ever came is found by some sweep, unless the buffer itself
    lost it before one (overwritten at [7], or gone beyond [63])."""
    buffer = AlarmBuffer(at_once=at_once)
    previous: SweepResult | None = None
    found: set[LogEntry] = set()
    came: list[Alarm] = []
    for kind, n in [*script, ("sweep", 0)]:
        if kind == "come":
            buffer.come(7000 + n, n)
            came.append(buffer.places[-1])
        elif kind == "go":
            buffer.go(n)
        else:
            result = sweep(buffer, previous)
            assert result is not None
            assert result == sweep(buffer)
            assert set(result.entries) == buffer.held()
            found |= set(result.entries)
            previous = result
    assert {_entry(a) for a in came} - found <= buffer.dropped


@settings(max_examples=300)
@given(at_once=st.booleans(), script=steps, refused=st.sampled_from([2123, 2124, 2145]))
def test_with_a_detail_refused_a_sweep_still_reads_what_a_whole_one_does(
    at_once: bool, script: list[Step], refused: int
) -> None:
    """A drive that refuses one of the details (value, ms or days): the same alarm again
    looks like the last sweep's newest, so none is taken as the mark, and every alarm the
    buffer holds is still found, as many times as it holds it."""
    buffer = AlarmBuffer(at_once=at_once)

    def drive(read: Read) -> int | None:
        return None if read.pnu == refused else buffer(read)

    previous: SweepResult | None = None
    for kind, n in [*script, ("sweep", 0)]:
        if kind == "come":
            buffer.come(7000 + n, n)
        elif kind == "go":
            buffer.go(n)
        else:
            result = sweep(drive, previous)
            assert result is not None
            assert result == sweep(drive)
            assert len(result.entries) == len(buffer.places) + len(buffer.history)
            assert sorted(e.code for e in result.entries) == sorted(
                a.code for a in buffer.places + buffer.history
            )
            previous = result
