"""The PROFIdrive fault buffer as the profile and the makers' manuals word it, kept here by
the test: P950[0] fault situations of P950[1] messages, situation s's message m at
subindex s x P950[1] + m (Siemens PROFIdrive application example PDRV V4.2); messages
entered in the sequence they are detected, a situation lasting from its first fault to
its acknowledgement (ABB RETA-02, pp. 100-102); [0] the active situation, [1] the latest
acknowledged, the oldest dropped (VACON 100, Control Techniques SI-PROFIBUS); P944
changing with every change, wrapping from 0xFFFF to 1 (PDRV). P948 in the type its
description names: Unsigned16 "seconds since the last fault occurred" (ABB RPBA-01), a
TimeDifference with or without date (53, 54), Unsigned32 seconds (PDRV), TimeOfDay with
date (12). What the documents leave open is left out of the runs: a fault beyond a
situation's last message, an acknowledgement with none active."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol.logs import (
    PROFIDRIVE_FAULT_BUFFER,
    Age,
    Kind,
    LogEntry,
    NoSuchLog,
    Opaque,
    Read,
    Runtime,
)
from pkwbus.protocol.logs.model import MS_PER_DAY
from pkwbus.protocol.logs.profidrive import COUNTER, MESSAGES, SITUATIONS, TIME_TYPE
from tests.protocol.logs.test_logs import sweep

LOG = PROFIDRIVE_FAULT_BUFFER
U16, U32, TIME_OF_DAY, TIME_DIFFERENCE, TIME_DIFFERENCE_MS = 6, 7, 12, 53, 54
_ARRAY, _READ_ONLY = 1 << 14, 1 << 9  # identifier bits (Danfoss MG.33.C4.02, section 5)


@dataclass
class Message:
    number: int
    value: int
    at: float  # seconds of the drive's clock (the test's)


@dataclass
class PdBuffer:
    """The buffer as the documents word it. ``now``: the drive's clock, in seconds; ``kind``:
    P948's data type as its description says (None: the drive refuses the description)."""

    situations: int = 8
    messages: int = 8
    kind: int | None = TIME_DIFFERENCE
    now: float = 0.0
    held: list[list[Message]] = field(default_factory=list)
    counter: int = 0
    refused: frozenset[int] = frozenset()  # parameters the drive refuses

    def __post_init__(self) -> None:
        self.held = [[] for _ in range(self.situations)]

    def fault(self, number: int, value: int) -> bool:
        """A fault is detected: into the active situation; False where it is full (what a
        fault beyond its last message does is not documented: the runs make none)."""
        active = self.held[0]
        if len(active) >= self.messages:
            return False
        active.append(Message(number, value, self.now))
        self._changed()
        return True

    def acknowledge(self) -> bool:
        """The situations move down by one, the oldest dropped; False with none active."""
        if not self.held[0]:
            return False
        self.held = [[], *self.held[:-1]]
        self._changed()
        return True

    def _changed(self) -> None:
        self.counter = self.counter % 0xFFFF + 1  # 0xFFFF wraps to 1

    def place(self, i: int) -> Message | None:
        situation, message = divmod(i, self.messages)
        there = self.held[situation] if situation < self.situations else []
        return there[message] if message < len(there) else None

    def time(self, m: Message) -> int:
        """P948 of ``m`` read now, in the described type."""
        ms = round(m.at * 1000)
        days, within = divmod(ms, MS_PER_DAY)
        if self.kind == U16:
            return min(math.floor(self.now - m.at), 0xFFFF)
        if self.kind in (TIME_DIFFERENCE, TIME_OF_DAY):
            return within << 16 | days
        if self.kind == TIME_DIFFERENCE_MS:
            return ms
        return ms // 1000

    def entries(self) -> list[LogEntry]:
        """What the buffer holds, newest first, as the reader should give it."""
        return [
            LogEntry(Kind.FAULT, m.number, None if 949 in self.refused else m.value, self.stamp(m))
            for situation in self.held
            for m in reversed(situation)
        ]

    def stamp(self, m: Message) -> Runtime | Opaque | Age | None:
        i = next(i for i in range(self.situations * self.messages) if self.place(i) is m)
        if self.kind is None or 948 in self.refused:
            return None
        raw = self.time(m)
        if self.kind == U16:
            return Age(raw, Read(948, i), 0xFFFF)
        if self.kind == TIME_DIFFERENCE:
            return Runtime(round(m.at * 1000))
        if self.kind == TIME_DIFFERENCE_MS:
            return Runtime(raw)
        if self.kind == TIME_OF_DAY:
            return Opaque(round(m.at * 1000))
        return Opaque(raw)

    def __call__(self, read: Read) -> int | None:
        i, pnu = read.index, read.pnu
        if pnu in self.refused:
            return None
        if read.element:
            if read.element != 1 or pnu != 948 or self.kind is None:
                return None
            return self.kind | _ARRAY | _READ_ONLY
        if pnu == 944:
            return self.counter
        if pnu == 950:
            return (self.situations, self.messages)[i] if i < 2 else None
        if not 0 <= i < self.situations * self.messages or pnu not in (947, 948, 949):
            return None
        m = self.place(i)
        if m is None:
            return 0
        return {947: m.number, 949: m.value, 948: self.time(m)}[pnu]


def test_the_newest_situation_first_and_in_a_situation_the_latest_message_first() -> None:
    buffer = PdBuffer()
    buffer.fault(1, 10)
    buffer.now = 5
    buffer.fault(2, 20)
    buffer.acknowledge()
    buffer.now = 9
    buffer.fault(3, 30)
    found = sweep(LOG, buffer)
    assert found is not None and found.runtime is None
    assert found.entries == (
        LogEntry(Kind.FAULT, 3, 30, Runtime(9000)),
        LogEntry(Kind.FAULT, 2, 20, Runtime(5000)),
        LogEntry(Kind.FAULT, 1, 10, Runtime(0)),
    )
    assert buffer(Read(947, 0)) == 3 and buffer(Read(947, 8)) == 1  # as the profile lays it


def test_an_acknowledgement_moves_the_situations_and_the_oldest_is_dropped() -> None:
    buffer = PdBuffer(situations=8, messages=1)  # VACON 100: [0] active, [7] the oldest
    for code in range(1, 11):
        buffer.now += 60
        buffer.fault(code, 0)
        buffer.acknowledge()
    found = sweep(LOG, buffer)
    assert found is not None
    assert [e.code for e in found.entries] == [10, 9, 8, 7, 6, 5, 4]  # [0] empty; 1-3 dropped


def test_a_change_while_the_buffer_is_read_means_read_again() -> None:
    buffer = PdBuffer()
    buffer.fault(1, 0)

    def fault_after(n: int) -> None:
        if n == 1:
            buffer.fault(2, 0)

    assert sweep(LOG, buffer, fault_after) is None
    assert sweep(LOG, buffer) is not None


def test_the_counter_wraps_from_its_top_to_one_and_a_change_there_is_seen() -> None:
    buffer = PdBuffer(counter=0xFFFE)
    buffer.fault(1, 0)
    assert buffer.counter == 0xFFFF

    def fault_after(n: int) -> None:
        if n == 1:
            buffer.fault(2, 0)

    assert sweep(LOG, buffer, fault_after) is None
    assert buffer.counter == 1


def test_an_empty_buffer_costs_the_shape_the_numbers_and_the_counter() -> None:
    buffer = PdBuffer(situations=8, messages=1)
    s = LOG.sweep()
    rounds = []
    while reads := s.next():
        rounds.append(reads)
        s.feed({r: buffer(r) for r in reads})
    assert rounds == [
        (COUNTER, SITUATIONS, MESSAGES, TIME_TYPE),
        tuple(Read(947, i) for i in range(8)),
        (COUNTER,),
    ]
    result = s.result()
    assert result is not None and result.entries == ()


def test_the_watch_is_the_fault_message_counter_alone() -> None:
    assert LOG.watch() == (Read(944),)
    assert LOG.runtime == ()


@pytest.mark.parametrize("refused", [950])
def test_a_drive_that_refuses_p950_keeps_no_such_buffer(refused: int) -> None:
    buffer = PdBuffer(refused=frozenset({refused}))
    with pytest.raises(NoSuchLog, match="P950"):
        sweep(LOG, buffer)


@pytest.mark.parametrize(("situations", "messages"), [(0, 8), (8, 0), (257, 1), (17, 16)])
def test_a_shape_with_no_place_or_beyond_a_pkw_index_is_no_buffer_read(
    situations: int, messages: int
) -> None:
    with pytest.raises(NoSuchLog, match="P950 gives"):
        sweep(LOG, PdBuffer(situations=situations, messages=messages))


@pytest.mark.parametrize(
    ("situations", "messages"),
    [
        (8, 8),  # Siemens (the PDRV example), LS S100
        (8, 1),  # VACON 100, Control Techniques SI-PROFIBUS
        (40, 1),  # VACON OPTE9
        (64, 1),  # ABB RETA-02 / RPBA-01, Array[64] (P950's split not documented)
        (16, 16),  # the most places a PKW index reaches
    ],
)
def test_each_makers_shape_is_read_whole(situations: int, messages: int) -> None:
    buffer = PdBuffer(situations=situations, messages=messages, kind=TIME_DIFFERENCE_MS)
    for k in range(3 * situations):  # fills every situation, a full one's last place too
        buffer.now += 1.5
        buffer.fault(100 + k % 50, k)
        if k % 3 == 2 or messages == 1:
            buffer.acknowledge()
    found = sweep(LOG, buffer)
    assert found is not None
    assert list(found.entries) == buffer.entries()
    assert len(found.entries) == sum(len(s) for s in buffer.held) > 0


@pytest.mark.parametrize(
    ("kind", "stamp"),
    [
        (U16, Age(3723, Read(948, 0), 0xFFFF)),  # its age when the drive answered the read
        (TIME_DIFFERENCE, Runtime.of(2, 3_600_000)),  # ms and days
        (TIME_DIFFERENCE_MS, Runtime(2 * MS_PER_DAY + 3_600_000)),
        (U32, Opaque(2 * 86_400 + 3600)),  # seconds, from when not said
        (TIME_OF_DAY, Opaque(2 * MS_PER_DAY + 3_600_000)),  # ms since 1984-01-01
        (8, Opaque(2 * 86_400 + 3600)),  # another type: no time a document explains
        (None, None),  # the description refused: P948 is not read
    ],
)
def test_the_fault_time_is_read_as_p948_is_described(
    kind: int | None, stamp: Runtime | Opaque | Age | None
) -> None:
    buffer = PdBuffer(situations=8, messages=1, kind=kind, now=2 * 86_400 + 3600)
    buffer.fault(7, 1)
    buffer.now += 3723
    reads: list[Read] = []

    def drive(read: Read) -> int | None:
        reads.append(read)
        return buffer(read)

    found = sweep(LOG, drive)
    assert found is not None
    assert found.entries == (LogEntry(Kind.FAULT, 7, 1, stamp),)
    assert (Read(948, 0) in reads) == (kind is not None)


def test_a_fault_value_or_time_the_drive_refuses_is_left_out() -> None:
    buffer = PdBuffer(refused=frozenset({949, 948}))  # ABB RPBA-01 lists no P949
    buffer.fault(5, 9)
    found = sweep(LOG, buffer)
    assert found is not None
    assert found.entries == (LogEntry(Kind.FAULT, 5, None, None),)


def test_a_six_byte_time_difference_is_ms_in_the_high_bytes_and_days_in_the_low() -> None:
    buffer = PdBuffer(kind=TIME_DIFFERENCE, now=100_000.25)  # past 65,536 s: ms > 16 bits
    buffer.fault(5, 9)
    assert buffer(Read(948, 0)) == (100_000_250 % MS_PER_DAY) << 16 | 1
    found = sweep(LOG, buffer)
    assert found is not None and found.entries[0].drive_time == Runtime(100_000_250)


Step = tuple[str, int]
steps = st.lists(
    st.one_of(
        st.tuples(st.just("fault"), st.integers(1, 6)),
        st.tuples(st.just("ack"), st.just(0)),
        st.tuples(st.just("wait"), st.integers(1, 40_000)),
        st.tuples(st.just("sweep"), st.just(0)),
    ),
    max_size=80,
)
shapes = st.sampled_from([(8, 8), (8, 1), (40, 1), (64, 1), (4, 2)])
kinds = st.sampled_from([U16, TIME_DIFFERENCE, TIME_DIFFERENCE_MS, U32, TIME_OF_DAY, None])


@settings(max_examples=300)
@given(shape=shapes, kind=kinds, script=steps)
def test_every_fault_the_buffer_held_at_a_sweep_is_found_with_its_time(
    shape: tuple[int, int], kind: int | None, script: list[Step]
) -> None:
    """Any run of faults, acknowledgements and waits with sweeps between: each sweep gives
    exactly what the buffer holds, newest first, each fault once; a fault's time is its
    own where the type says when it came (an age: to the second before the read), its
    drive's number where the type says not from when it counts, none where P948 is not
    described; so every fault the buffer held at some sweep is found."""
    buffer = PdBuffer(*shape, kind=kind, now=1000.0)
    entered: list[Message] = []
    found: set[int] = set()  # ids of the messages found
    held_at_sweeps: set[int] = set()
    for kind_of_step, n in [*script, ("sweep", 0)]:
        if kind_of_step == "fault":
            buffer.now += 0.25
            if buffer.fault(n, 100 + len(entered)):  # each fault a value of its own
                entered.append(buffer.held[0][-1])
        elif kind_of_step == "ack":
            buffer.acknowledge()
        elif kind_of_step == "wait":
            buffer.now += n / 8
        else:
            result = sweep(LOG, buffer)
            assert result is not None
            assert list(result.entries) == buffer.entries()
            this_sweep = set()
            for entry in result.entries:
                (m,) = [m for m in entered if m.value == entry.value]
                this_sweep.add(id(m))
                if isinstance(entry.drive_time, Age):
                    placed = buffer.now - entry.drive_time.seconds  # when the age was read
                    assert m.at <= placed < m.at + 1 or entry.drive_time.seconds == 0xFFFF
                elif isinstance(entry.drive_time, Runtime) and kind == TIME_DIFFERENCE:
                    assert entry.drive_time.ms == round(m.at * 1000)
            held = {id(m) for s in buffer.held for m in s}
            assert this_sweep == held and len(result.entries) == len(held)  # each once
            found |= this_sweep
            held_at_sweeps |= held
    assert found == held_at_sweeps
