"""Entries timed by their age (a PROFIdrive P948 of Unsigned16, "seconds since the last
fault occurred", ABB RPBA-01): the buffer of tests/protocol/logs/test_profidrive.py,
swept at any times, each entry placed where its age says and kept once, across sweeps
and restarts of pkwbus (the keys read back from the history)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol.logs import PROFIDRIVE_FAULT_BUFFER, LogEntry, Read
from pkwbus.service.history.ages import AGE_DRIFT, AGE_SLACK, AgedKeys
from pkwbus.service.history.store import DriveEvent
from pkwbus.service.history.watch import entry_key
from tests.protocol.logs.test_logs import sweep
from tests.protocol.logs.test_profidrive import U16, Message, PdBuffer

LOG = PROFIDRIVE_FAULT_BUFFER


class Kept:
    """The history of one drive: each key once, with the event first stored under it."""

    def __init__(self) -> None:
        self.events: dict[str, DriveEvent] = {}

    def sweep(self, buffer: PdBuffer, keys: AgedKeys, *, late: float = 0.1) -> list[DriveEvent]:
        """A sweep of ``buffer`` as the watcher makes it: the ages answered ``late`` seconds
        after the drive read them; what it stores."""
        found = sweep(LOG, buffer)
        assert found is not None
        now = buffer.now + late
        events = [_event(e, now) for e in found.entries]
        answered = {Read(948, i): now for i in range(buffer.situations * buffer.messages)}
        placed = keys.place(found.entries, events, answered)
        for e in placed:
            self.events.setdefault(e.key, e)
        return placed


def _event(e: LogEntry, now: float) -> DriveEvent:
    """An entry as the watcher gives it to be placed (before :class:`AgedKeys`)."""
    key, code, value, stamp = entry_key(e), str(e.code), e.value, str(e.drive_time)
    return DriveEvent("l", "d", key, "fault", code, e.code, "", value, None, "seen", stamp, now)


def fault(buffer: PdBuffer, code: int, value: int) -> Message:
    assert buffer.fault(code, value)
    return buffer.held[0][-1]


def test_an_aged_entry_is_placed_by_its_age_and_known_again_later() -> None:
    buffer = PdBuffer(situations=8, messages=1, kind=U16, now=1000.0)
    m = fault(buffer, 5, 0)
    kept, keys = Kept(), AgedKeys([])
    buffer.now += 30.4
    (first,) = kept.sweep(buffer, keys)
    assert first.time_source == "runtime" and first.time is not None
    assert m.at <= first.time < m.at + 1 + 0.1
    buffer.now += 3600.7
    (again,) = kept.sweep(buffer, keys)
    assert again.key == first.key and len(kept.events) == 1


def test_two_alike_in_one_sweep_are_two_entries() -> None:
    buffer = PdBuffer(situations=8, messages=1, kind=U16, now=1000.0)
    fault(buffer, 5, 0)
    buffer.acknowledge()
    buffer.now += 0.5  # within the same second
    fault(buffer, 5, 0)
    kept, keys = Kept(), AgedKeys([])
    buffer.now += 10
    assert len({e.key for e in kept.sweep(buffer, keys)}) == 2
    buffer.now += 10
    assert len({e.key for e in kept.sweep(buffer, keys)}) == 2
    assert len(kept.events) == 2


def test_after_a_restart_the_keys_kept_are_met_again() -> None:
    buffer = PdBuffer(situations=8, messages=1, kind=U16, now=1000.0)
    fault(buffer, 5, 0)
    kept = Kept()
    buffer.now += 100
    kept.sweep(buffer, AgedKeys([]))
    buffer.now += 7200  # pkwbus was down
    kept.sweep(buffer, AgedKeys(kept.events))  # the keys read back from the history
    assert len(kept.events) == 1


def test_an_entry_placed_beyond_its_slack_is_another_entry() -> None:
    """As where its age stood still while the drive was off (not documented either way)."""
    buffer = PdBuffer(situations=8, messages=1, kind=U16, now=1000.0)
    m = fault(buffer, 5, 0)
    kept, keys = Kept(), AgedKeys([])
    buffer.now += 100
    kept.sweep(buffer, keys)
    buffer.now += 600
    m.at += 1.5  # within the slack (2 s): the same entry
    kept.sweep(buffer, keys)
    assert len(kept.events) == 1
    m.at += 300  # the drive was off 300 s, its ages standing still
    kept.sweep(buffer, keys)
    assert len(kept.events) == 2


def test_an_age_at_the_top_of_its_number_keeps_its_entry_and_has_no_time() -> None:
    buffer = PdBuffer(situations=8, messages=1, kind=U16, now=1000.0)
    fault(buffer, 5, 0)
    buffer.acknowledge()
    kept, keys = Kept(), AgedKeys([])
    buffer.now += 60_000
    (placed,) = kept.sweep(buffer, keys)
    buffer.now += 86_400  # its age stands at 65,535 s
    (top,) = kept.sweep(buffer, keys)
    assert top.key == placed.key and len(kept.events) == 1
    fault(buffer, 6, 0)  # found first past the top: kept, with no time
    buffer.acknowledge()
    buffer.now += 70_000  # pkwbus was down meanwhile
    kept.sweep(buffer, AgedKeys(kept.events))
    late = [e for e in kept.events.values() if e.number == 6]
    assert [(e.time, e.time_source) for e in late] == [(None, "seen")]
    buffer.now += 3600
    kept.sweep(buffer, AgedKeys(kept.events))
    assert len(kept.events) == 2


Step = tuple[str, int]
steps = st.lists(
    st.one_of(
        st.tuples(st.just("fault"), st.integers(1, 3)),
        st.tuples(st.just("ack"), st.just(0)),
        st.tuples(st.just("wait"), st.integers(1, 20_000)),
        st.tuples(st.just("sweep"), st.integers(0, 2)),
        st.tuples(st.just("restart"), st.just(0)),
    ),
    max_size=80,
)


@settings(max_examples=300)
@given(
    shape=st.sampled_from([(8, 1), (40, 1), (8, 8), (4, 2)]),
    late=st.floats(0.0, 0.9),
    script=steps,
)
def test_every_aged_fault_is_kept_once_with_its_time(
    shape: tuple[int, int], late: float, script: list[Step]
) -> None:
    """Faults of few codes and one value (so that only their times tell them apart), swept
    at any times, the answers late by up to 0.9 s, pkwbus restarted between sweeps: every
    fault the buffer held at a sweep is kept under one key of its own, placed to within
    the second its age counts (and the answer's delay). Two alike faults are at least
    twice the slack of an age at its top apart (closer, they cannot be told apart: see
    the test below), and a change is swept before time goes on (pkwbus runs: P944 moved)."""
    apart = 2 * (AGE_SLACK + AGE_DRIFT * 0xFFFF) + 1
    buffer = PdBuffer(*shape, kind=U16, now=1000.0)
    kept, keys = Kept(), AgedKeys([])
    entered: list[Message] = []
    key_of: dict[int, str] = {}  # each message's key, once found
    changed = False

    def swept() -> None:
        placed = kept.sweep(buffer, keys, late=late)
        held = [m for s in buffer.held for m in reversed(s)]
        assert len(placed) == len(held)
        for m, event in zip(held, placed, strict=True):
            assert key_of.setdefault(id(m), event.key) == event.key  # the same key
            first = kept.events[event.key]
            assert first.time is not None
            assert m.at - 1e-6 <= first.time <= m.at + 1 + late + 1e-6

    for kind, n in [*script, ("sweep", 0)]:
        if kind == "fault":
            last = max((m.at for m in entered if m.number == n), default=-apart)
            buffer.now = max(buffer.now + 0.3, last + apart)
            if buffer.fault(n, 0):
                entered.append(buffer.held[0][-1])
                changed = True
        elif kind == "ack":
            changed |= buffer.acknowledge()
        elif kind == "wait":
            if changed:
                swept()
                changed = False
            buffer.now += n / 4
        elif kind == "restart":
            keys = AgedKeys(kept.events)
        else:
            buffer.now += n * 0.37
            swept()
            changed = False
    assert len(set(key_of.values())) == len(key_of)  # no two faults under one key
    assert set(kept.events) == set(key_of.values())  # and nothing else kept


def test_alike_faults_within_their_slack_cannot_be_told_apart_once_one_has_left() -> None:
    """Four of one code and value within a second, in a buffer of four situations: the
    first leaves it between two sweeps, and by their ages the second is taken for it,
    the third for the second: the three are kept as two (the limit the README names)."""
    buffer = PdBuffer(situations=4, messages=2, kind=U16, now=1000.0)
    kept, keys = Kept(), AgedKeys([])
    fault(buffer, 1, 0)
    buffer.acknowledge()
    buffer.now += 0.3
    fault(buffer, 1, 0)
    kept.sweep(buffer, keys)
    for _ in range(2):
        buffer.acknowledge()
        buffer.now += 0.3
        fault(buffer, 1, 0)
    buffer.acknowledge()
    kept.sweep(buffer, keys)
    assert len(kept.events) == 3  # four faults
