"""The drives' logs as their documents lay them out: the SINAMICS fault buffer (S200
Operating Instructions, appendix A.3: 8 cases x 8 faults, shifted down on acknowledgement)
and the Danfoss alarm log (15-30..15-32, ten entries, the newest first)."""

from __future__ import annotations

from collections.abc import Callable

from pkwbus.protocol.logs import (
    DANFOSS_ALARM_LOG,
    SINAMICS_FAULT_BUFFER,
    DriveLog,
    Kind,
    LogEntry,
    Opaque,
    Read,
    Runtime,
    SweepResult,
)
from pkwbus.protocol.logs.model import MS_PER_DAY

Drive = Callable[[Read], int | None]  # what the drive answers to a read (None: refused)


def sweep(
    log: DriveLog,
    drive: Drive,
    between: Callable[[int], None] = lambda _: None,
    previous: SweepResult | None = None,
) -> SweepResult | None:
    """A sweep against ``drive`` (after ``previous``); ``between(n)`` runs after round
    ``n``. A sweep ends: at most a round per entry of the longest log (64) and a few."""
    s = log.sweep(previous)
    rounds = 0
    while reads := s.next():
        s.feed({r: drive(r) for r in reads})
        between(rounds)
        rounds += 1
        assert rounds < 70
    return s.result()


class FaultBuffer:
    """A SINAMICS fault buffer kept as the document words it, in the test."""

    def __init__(self) -> None:
        self.number = [0] * 64
        self.value = [0] * 64
        self.ms = [0] * 64
        self.days = [0] * 64
        self.counter = 0
        self.runtime = Runtime(0)

    def fault(self, number: int, value: int, at: Runtime) -> None:
        place = next((i for i in range(8) if not self.number[i]), 7)  # beyond 8: the eighth
        days, ms = divmod(at.ms, MS_PER_DAY)
        self.number[place], self.value[place], self.ms[place], self.days[place] = (
            number, value, ms, days,
        )  # fmt: skip
        self.counter += 1

    def acknowledge(self) -> None:
        """The cases move down by one; the 7th acknowledged case is dropped."""
        for column in (self.number, self.value, self.ms, self.days):
            column[8:] = column[:56]
            column[:8] = [0] * 8
        self.counter += 1

    def __call__(self, read: Read) -> int | None:
        i = read.index
        if read.pnu == 944:
            return self.counter
        if read.pnu == 2114:
            days, ms = divmod(self.runtime.ms, MS_PER_DAY)
            return ms if i == 0 else days
        column = {947: self.number, 949: self.value, 948: self.ms, 2130: self.days}
        return column[read.pnu][i] if read.pnu in column else None


def test_the_fault_buffer_newest_case_first_and_in_a_case_the_latest_fault_first() -> None:
    buffer = FaultBuffer()
    buffer.fault(7801, 12, Runtime.of(2, 1000))  # a case of two faults, acknowledged
    buffer.fault(7802, -5, Runtime.of(2, 1500))
    buffer.acknowledge()
    buffer.fault(30001, 4, Runtime.of(3, 20))  # the active case
    buffer.runtime = Runtime.of(3, 5000)
    found = sweep(SINAMICS_FAULT_BUFFER, buffer)
    assert found is not None and found.runtime == Runtime.of(3, 5000)
    assert found.entries == (
        LogEntry(Kind.FAULT, 30001, 4, Runtime.of(3, 20)),
        LogEntry(Kind.FAULT, 7802, -5, Runtime.of(2, 1500)),
        LogEntry(Kind.FAULT, 7801, 12, Runtime.of(2, 1000)),
    )


def test_an_acknowledgement_shifts_the_cases_but_no_entry_changes() -> None:
    """Entries are the same by content after the shift: indexes are never identity."""
    buffer = FaultBuffer()
    for n in range(3):
        buffer.fault(7800 + n, n, Runtime(1000 * n))
    before = sweep(SINAMICS_FAULT_BUFFER, buffer)
    buffer.acknowledge()
    after = sweep(SINAMICS_FAULT_BUFFER, buffer)
    assert before is not None and after is not None
    assert set(before.entries) == set(after.entries) and len(after.entries) == 3
    assert buffer.number[8:11] == [7800, 7801, 7802] and buffer.number[:8] == [0] * 8


def test_the_seventh_acknowledged_case_is_dropped() -> None:
    buffer = FaultBuffer()
    for case in range(9):
        buffer.fault(100 + case, case, Runtime(case))
        buffer.acknowledge()
    found = sweep(SINAMICS_FAULT_BUFFER, buffer)
    assert found is not None
    # The active case is empty; the 1st..7th acknowledged cases hold the 7 newest.
    assert [e.code for e in found.entries] == [108, 107, 106, 105, 104, 103, 102]


def test_beyond_eight_active_faults_only_the_eighth_place_is_overwritten() -> None:
    buffer = FaultBuffer()
    for n in range(10):
        buffer.fault(200 + n, n, Runtime(n))
    found = sweep(SINAMICS_FAULT_BUFFER, buffer)
    assert found is not None
    assert [e.code for e in found.entries] == [209, 206, 205, 204, 203, 202, 201, 200]


def test_a_change_while_the_buffer_is_read_means_read_again() -> None:
    buffer = FaultBuffer()
    buffer.fault(7801, 1, Runtime(10))

    def trips_after_round(n: int) -> None:
        if n == 0:  # after the fault numbers were read: a new fault comes
            buffer.fault(7802, 2, Runtime(20))

    assert sweep(SINAMICS_FAULT_BUFFER, buffer, trips_after_round) is None
    found = sweep(SINAMICS_FAULT_BUFFER, buffer)
    assert found is not None and [e.code for e in found.entries] == [7802, 7801]


def test_an_empty_buffer_costs_one_round_and_the_counter() -> None:
    buffer = FaultBuffer()
    s = SINAMICS_FAULT_BUFFER.sweep()
    reads = 0
    while batch := s.next():
        reads += len(batch)
        s.feed({r: buffer(r) for r in batch})
    assert reads == 3 + 64 + 1
    result = s.result()
    assert result is not None and result.entries == ()


def test_the_watch_is_the_change_counter_alone() -> None:
    assert SINAMICS_FAULT_BUFFER.watch() == (Read(944),)


def test_a_refused_time_leaves_the_entry_without_one() -> None:
    buffer = FaultBuffer()
    buffer.fault(7801, 1, Runtime(10))

    def no_days(read: Read) -> int | None:
        return None if read.pnu in (2130, 2114) else buffer(read)

    found = sweep(SINAMICS_FAULT_BUFFER, no_days)
    assert found is not None and found.runtime is None
    assert found.entries == (LogEntry(Kind.FAULT, 7801, 1, None),)


class AlarmLog:
    """The Danfoss alarm log kept as its (secondary) source words it: newest first, 10."""

    def __init__(self) -> None:
        self.entries: list[tuple[int, int, int]] = []

    def trip(self, code: int, value: int, time: int) -> None:
        self.entries = [(code, value, time), *self.entries][:10]

    def __call__(self, read: Read) -> int | None:
        column = {1530: 0, 1531: 1, 1532: 2}[read.pnu]
        return self.entries[read.index][column] if read.index < len(self.entries) else 0


def test_the_danfoss_alarm_log_newest_first_with_an_opaque_time() -> None:
    log = AlarmLog()
    for n in range(12):
        log.trip(10 + n, 100 * n, 5000 + n)
    found = sweep(DANFOSS_ALARM_LOG, log)
    assert found is not None and found.runtime is None
    assert len(found.entries) == 10  # the two oldest dropped
    assert found.entries[0] == LogEntry(Kind.FAULT, 21, 1100, Opaque(5011))
    assert [e.code for e in found.entries] == list(range(21, 11, -1))


def test_a_trip_while_the_danfoss_log_is_read_means_read_again() -> None:
    log = AlarmLog()
    log.trip(13, 1, 7)
    assert sweep(DANFOSS_ALARM_LOG, log, lambda n: log.trip(14, 2, 8) if n == 1 else None) is None
    empty = AlarmLog()
    assert (
        sweep(DANFOSS_ALARM_LOG, empty, lambda n: empty.trip(9, 0, 1) if n == 0 else None) is None
    )
    found = sweep(DANFOSS_ALARM_LOG, log)
    assert found is not None and [e.code for e in found.entries] == [14, 13]


def test_runtime_in_days_and_milliseconds() -> None:
    assert Runtime.of(1, 5) == Runtime(MS_PER_DAY + 5)
    assert str(Runtime.of(3, 3_723_004)) == "3 d 01:02:03.004"


def test_an_empty_danfoss_log_is_read_whole_and_has_no_entries() -> None:
    found = sweep(DANFOSS_ALARM_LOG, AlarmLog())
    assert found is not None and found.entries == ()
