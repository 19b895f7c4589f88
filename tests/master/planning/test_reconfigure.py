"""A reload on a running planner, on a fake clock: drives added and removed, polls changed.

A drive added is polled from now on while the others keep their due times; a drive
removed has its queued jobs cancelled with the reload's reason and is sent nothing
more (an exchange of it on the wire ends at its result); a poll kept keeps its due
time (a new interval counts from its next due time on), a new one is due now, one
removed is never sent again, also when it was on the wire at the update.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.planning.answers import ErrorKind, ExchangeResult, Failure
from pkwbus.master.planning.jobs import Cancelled, Job, JobKind, Priority
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import (
    Described,
    Finished,
    Idle,
    Overrun,
    PollSpec,
    Redecoded,
    Send,
)
from pkwbus.master.planning.planner import NOT_HERE, Planner
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.sim import SimTiming, Simulator
from tests.master.planning.test_describing import CURRENT, polls_of
from tests.master.planning.test_describing import line as describing_line
from tests.master.planning.test_planner import EXCHANGE, MS, FakeLine, drives

REASON = "gone from the configuration"
SLACK = 1e-9  # float sums of intervals
LATE = 8 * EXCHANGE  # a poll waits at most for the few exchanges due before it


def line_of(
    planned: list[int],
    present: list[int],
    pnus: list[int],
    every: float,
    *,
    protocol: str = "fc",
    timing: SimTiming | None = None,
) -> FakeLine:
    """Drives ``planned`` on the line, the simulator answering for ``present``."""
    sim = Simulator(protocol, present, timing=timing or SimTiming(response_delay=0.0), seed=7)
    return FakeLine(Planner(drives(protocol, planned, pnus, every), poll_deadline=0.5), sim)


def poll(address: int, pnu: int, every: float, *, protocol: str = "fc") -> PollSpec:
    target = DriveTarget.create(protocol, address)
    return PollSpec(str(pnu), 0, pkw.read(target.dialect, pnu), every)


def read_telegram(address: int, pnu: int) -> bytes:
    target = DriveTarget.create("fc", address)
    return SerialCarrier(target).telegram(pkw.read(target.dialect, pnu))


def dialect_of(address: int) -> pkw.Dialect:
    return DriveTarget.create("fc", address).dialect


def sent_at(line: FakeLine, drive: str, telegram: bytes, since: int = 0) -> list[float]:
    """When ``telegram`` went out to ``drive`` (from the ``since``-th exchange on)."""
    return [
        t
        for s, t in zip(line.sent[since:], line.times[since:], strict=True)
        if s.drive == drive and s.telegram == telegram
    ]


def on_time(times: list[float], first: float, every: float) -> None:
    """The k-th time is the k-th due time (``first + k * every``), a few exchanges late at
    most: none missed, none early, none an interval late."""
    for k, t in enumerate(times):
        due = first + k * every
        assert due - SLACK <= t <= due + LATE, (k, t, due)


def hold(line: FakeLine, drive: str, telegram: bytes | None = None, within: float = 5.0) -> Send:
    """Run the line until its next exchange is ``drive``'s (with ``telegram``): that one goes
    out and is left unanswered (on the wire)."""
    send = hold_if(line, drive, telegram, within)
    assert send is not None, f"no exchange of {drive} within {within} s"
    return send


def hold_if(
    line: FakeLine, drive: str, telegram: bytes | None = None, within: float = 5.0
) -> Send | None:
    """:func:`hold`, or None when no such exchange comes within ``within`` seconds."""
    end = line.now + within
    while line.now < end:
        action = line.planner.next_action(line.now)
        line._collect()
        if isinstance(action, Idle):
            line.now = max(line.now, min(action.until, end))
            continue
        line.times.append(line.now)
        line.sent.append(action)
        if action.drive == drive and telegram in (None, action.telegram):
            return action
        answer(line, action)
    return None


def answer(line: FakeLine, send: Send, result: ExchangeResult | None = None) -> None:
    """The result of ``send`` (the simulator's answer unless given) to the planner."""
    if result is None:
        result = line.answer(send)
    else:
        line.now += EXCHANGE
    line.results.append(result)
    line.planner.exchanged(send, result, line.now)
    line._collect()


def to_drive(line: FakeLine, address: int, since: int, protocol: str = "fc") -> list[Send]:
    """What went to drive ``address`` (by its name or its address) from the ``since``-th
    exchange on."""
    adr = SerialCarrier(DriveTarget.create(protocol, address)).address
    return [s for s in line.sent[since:] if s.drive == f"d{address}" or s.address == adr]


def update_polls(
    planner: Planner, drive: str, polls: Sequence[PollSpec], now: float
) -> list[PollSpec]:
    """The drive's polls as a reload gives them (the rest of its spec as it is)."""
    spec = dataclasses.replace(planner.drive(drive).spec, polls=tuple(polls))
    return planner.update_polls(spec, now)


def polled_since(line: FakeLine, drive: str, pnu: int, since: int) -> list[Finished]:
    """The polls of ``pnu`` that ended for ``drive`` from the ``since``-th event on."""
    return [
        e for e in line.events[since:]
        if isinstance(e, Finished) and e.drive == drive and isinstance(e.work, PollSpec)
        and e.work.request.pnu == pnu
    ]  # fmt: skip


def job(line: FakeLine, drive: str, request: pkw.PkwRequest, priority: Priority) -> Job:
    kind = JobKind.WRITE if request.is_write else JobKind.READ
    queued = Job(drive, request, kind, priority, line.now + 30.0)
    line.planner.submit(queued, line.now)
    line._collect()
    return queued


# ---------------------------------------------------------------- add_drive


def test_an_added_drive_is_polled_at_once_and_the_others_keep_their_due_times() -> None:
    every = 100 * MS
    line = line_of([1, 2], [1, 2, 3], [1613, 1614], every)
    line.run(1.03)  # the polls went out at 1.0, are due again at 1.1
    added = line.now
    before = len(line.sent)
    line.planner.add_drive(drives("fc", [3], [1613, 1614], every)[0], line.now)
    line._collect()
    line.run(3.0 - added)
    # Its polls are due now: they go out first, at once, then at their interval.
    assert [s.drive for s in line.sent[before : before + 2]] == ["d3", "d3"]
    assert line.times[before] == added
    assert not [e for e in line.events if isinstance(e, Overrun)], "due now: none is late"
    for pnu in (1613, 1614):
        times = sent_at(line, "d3", read_telegram(3, pnu), before)
        assert len(times) >= (3.0 - added) / every - 1
        on_time(times, added, every)
    assert line.polls_ok("d3") >= 2 * ((3.0 - added) / every - 1)
    # The others went on at their own due times, across the addition.
    for address in (1, 2):
        for pnu in (1613, 1614):
            times = sent_at(line, f"d{address}", read_telegram(address, pnu))
            assert len(times) >= 3.0 / every - 1
            on_time(times, 0.0, every)
    assert not [e for e in line.events if isinstance(e, Overrun)]


def test_a_drive_added_while_the_line_is_down_is_polled_once_it_is_up() -> None:
    line = line_of([1], [1, 2], [1613], 50 * MS)
    line.run(0.2)
    line.planner.line_down(line.now)
    line.planner.add_drive(drives("fc", [2], [1613], 50 * MS)[0], line.now)
    assert isinstance(line.planner.next_action(line.now), Idle)
    line.now += 1.0
    line.planner.line_up(line.now)
    before = len(line.sent)
    line.run(0.5)
    assert sent_at(line, "d2", read_telegram(2, 1613), before)[0] <= line.times[before] + LATE


# ---------------------------------------------------------------- remove_drive


def test_a_removed_drives_queued_jobs_end_cancelled_and_nothing_more_goes_to_it() -> None:
    line = line_of([1, 2], [1, 2], [1613], 50 * MS)
    line.run(0.2)
    dialect = dialect_of(2)
    write = job(line, "d2", pkw.write(dialect, 341, 777, pkw.Width.DWORD), Priority.WRITE)
    read = job(line, "d2", pkw.read(dialect, 1530), Priority.READ)
    background = job(line, "d2", pkw.read(dialect, 1530, 1), Priority.BACKGROUND)
    old = line.sim.drives[2].value(341)
    spec = line.planner.drive("d2").spec
    events, before, polled = len(line.events), len(line.sent), line.polls_ok("d1")
    line.planner.remove_drive("d2", REASON, line.now)
    line._collect()
    for queued in (write, read, background):
        (ended,) = line.finished(queued)
        assert ended.outcome == Cancelled(REASON)
        assert ended.tally is None  # never sent
    line.run(2.0)
    assert to_drive(line, 2, before) == []
    assert line.sim.drives[2].value(341) == old
    told = [e for e in line.events[events:] if getattr(e, "drive", None) == "d2"]
    assert [e.work for e in told if isinstance(e, Finished)] == [write, read, background]
    assert len(told) == 3, "nothing else of it after its removal"
    assert line.polls_ok("d1") >= polled + 2.0 / (50 * MS) - 2  # the other drive goes on
    # A job for it submitted now (checked before the reload took it away) ends at once, for
    # its caller alone, and nothing goes out.
    sent, late = len(line.sent), job(line, "d2", pkw.write(dialect, 341, 1, pkw.Width.DWORD),
                                     Priority.WRITE)  # fmt: skip
    (ended,) = line.finished(late)
    assert ended.outcome == Cancelled(NOT_HERE) and ended.gone and ended.tally is None
    line.run(0.5)
    assert to_drive(line, 2, sent) == [] and line.sim.drives[2].value(341) == old
    with pytest.raises(KeyError):
        line.planner.update_polls(dataclasses.replace(spec, polls=()), line.now)


def test_a_removed_drives_poll_on_the_wire_ends_at_its_result_and_nothing_follows() -> None:
    line = line_of([1, 2], [1, 2], [1613], 50 * MS)
    line.run(0.2)
    send = hold(line, "d2")
    before = len(line.sent)
    line.planner.remove_drive("d2", REASON, line.now)
    line._collect()
    events = len(line.events)
    answer(line, send)  # accepted: no KeyError
    # Its poll's result is nobody's: nothing of it is told (a drive of its name could be
    # back already), and nothing follows it.
    line.run(2.0)
    assert to_drive(line, 2, before) == []
    assert [e for e in line.events[events:] if getattr(e, "drive", None) == "d2"] == []
    assert "d2" not in line.planner._roster.leaving


def test_a_removed_drives_read_on_the_wire_ends_at_its_answer() -> None:
    line = line_of([1, 2], [1, 2], [1613], 50 * MS)
    line.run(0.2)
    read = job(line, "d2", pkw.read(dialect_of(2), 341), Priority.READ)
    send = hold(line, "d2", read_telegram(2, 341))
    before = len(line.sent)
    line.planner.remove_drive("d2", REASON, line.now)
    line._collect()
    assert not line.finished(read)  # on the wire: it ends at its answer
    answer(line, send)
    (ended,) = line.finished(read)
    assert isinstance(ended.outcome, Answered) and ended.tally is not None
    line.run(1.0)
    assert to_drive(line, 2, before) == []


def test_a_removed_drives_read_whose_exchange_fails_is_not_repeated() -> None:
    """The exchange out when the drive went gets no answer: the read ends (cancelled with
    the reload's reason), and it is not tried again."""
    line = line_of([1, 2], [1, 2], [1613], 50 * MS)
    line.run(0.2)
    read = job(line, "d2", pkw.read(dialect_of(2), 341), Priority.READ)
    send = hold(line, "d2", read_telegram(2, 341))
    before = len(line.sent)
    line.planner.remove_drive("d2", REASON, line.now)
    answer(line, send, Failure(ErrorKind.TIMEOUT, "no answer"))
    line.run(1.0)
    assert to_drive(line, 2, before) == []
    (ended,) = line.finished(read)
    assert isinstance(ended.outcome, Cancelled)
    assert ended.outcome.reason == REASON  # not "in maintenance": it is gone


def test_a_removed_drives_acknowledged_write_on_the_wire_still_counts() -> None:
    line = line_of([1, 2], [1, 2], [1613], 50 * MS)
    line.run(0.2)
    dialect = dialect_of(2)
    write = job(line, "d2", pkw.write(dialect, 341, 777, pkw.Width.DWORD), Priority.WRITE)
    target = DriveTarget.create("fc", 2)
    send = hold(line, "d2", SerialCarrier(target).telegram(write.request))  # after its read first
    before = len(line.sent)
    line.planner.remove_drive("d2", REASON, line.now)
    line._collect()
    assert not line.finished(write)
    answer(line, send)
    (ended,) = line.finished(write)
    assert isinstance(ended.outcome, Answered)
    assert line.sim.drives[2].value(341) == 777
    line.run(1.0)
    assert to_drive(line, 2, before) == []


def test_a_removed_drives_write_is_not_sent_after_the_read_before_it() -> None:
    """The read before a change is on the wire when the drive goes: the change itself never
    goes out, and the job ends cancelled with the reload's reason."""
    line = line_of([1, 2], [1, 2], [1613], 50 * MS)
    line.run(0.2)
    dialect = dialect_of(2)
    old = line.sim.drives[2].value(341)
    write = job(line, "d2", pkw.write(dialect, 341, 777, pkw.Width.DWORD), Priority.WRITE)
    send = hold(line, "d2", read_telegram(2, 341))
    before = len(line.sent)
    line.planner.remove_drive("d2", REASON, line.now)
    answer(line, send)
    line.run(1.0)
    assert to_drive(line, 2, before) == []
    assert line.sim.drives[2].value(341) == old
    (ended,) = line.finished(write)
    assert isinstance(ended.outcome, Cancelled)
    assert ended.outcome.reason == REASON  # not "in maintenance": it is gone


def test_a_removed_drives_lagging_job_between_its_tries_ends_at_once() -> None:
    """Its read was answered "not yet" and waits for its repeat (not on the wire): it ends
    with the removal, and the repeat never goes out."""
    timing = SimTiming(response_delay=0.0, lag_telegrams=1000, lag_mode="none")
    line = line_of([1, 2], [1, 2], [], 1.0, protocol="uss", timing=timing)
    dialect = DriveTarget.create("uss", 2).dialect
    read = job(line, "d2", pkw.read(dialect, 1121), Priority.READ)
    send = hold(line, "d2")
    answer(line, send)  # "not yet"
    assert not line.finished(read) and not line.planner.drive("d2").busy
    before = len(line.sent)
    line.planner.remove_drive("d2", REASON, line.now)
    line._collect()
    (ended,) = line.finished(read)
    assert ended.outcome == Cancelled(REASON)
    line.run(1.0)
    assert to_drive(line, 2, before, "uss") == []


def test_a_drive_removed_and_added_again_while_its_exchange_is_out() -> None:
    """A reload that changes a drive (its address, say) removes it and adds it again under
    its name while an exchange of the old one is on the wire: the old one's result ends the
    old one's work (the job's caller is answered), the new one is polled."""
    line = line_of([1, 2], [1, 2, 3], [1613], 50 * MS)
    line.run(0.2)
    read = job(line, "d2", pkw.read(dialect_of(2), 341), Priority.READ)
    send = hold(line, "d2", read_telegram(2, 341))
    before = len(line.sent)
    line.planner.remove_drive("d2", REASON, line.now)
    moved = drives("fc", [3], [1613], 50 * MS)[0]
    line.planner.add_drive(dataclasses.replace(moved, name="d2"), line.now)
    answer(line, send)
    line.run(1.0)
    assert len(line.finished(read)) == 1, "the old drive's job ends"
    assert [
        s
        for s in line.sent[before:]
        if s.address == SerialCarrier(DriveTarget.create("fc", 2)).address
    ] == []
    assert sent_at(line, "d2", read_telegram(3, 1613), before), "the new one is polled"
    assert line.planner._roster.leaving == {}


def test_a_drive_added_after_one_removed_before_its_first_poll() -> None:
    """The drive removed had not had its turn yet (its claim still waits in the planner's
    heap, at the same due time as the new drive's polls): the drive added takes its place
    in the line's order, and the two are told apart."""
    line = line_of([1, 2], [1, 2, 3], [1613], 50 * MS)  # its line up: all polls due now
    line.planner.remove_drive("d2", REASON, line.now)
    line.planner.add_drive(drives("fc", [3], [1613], 50 * MS)[0], line.now)
    line.run(1.0)
    assert to_drive(line, 2, 0) == []
    on_time(sent_at(line, "d1", read_telegram(1, 1613)), 0.0, 50 * MS)
    on_time(sent_at(line, "d3", read_telegram(3, 1613)), 0.0, 50 * MS)
    assert len(sent_at(line, "d3", read_telegram(3, 1613))) == 20


# ---------------------------------------------------------------- update_polls


@pytest.mark.parametrize("every", [3.0, 0.25])
def test_a_new_interval_counts_from_the_polls_next_due_time(every: float) -> None:
    line = line_of([1, 2], [1, 2], [1613, 1614], 1.0)
    line.run(2.5)  # polled at 0, 1 and 2: due again at 3
    assert line.now == 2.5
    first, second = line.planner.drive("d1").spec.polls
    polls = (dataclasses.replace(first, every=every), second)
    assert update_polls(line.planner, "d1", polls, line.now) == list(polls)
    before = len(line.sent)
    line.run(7.5)  # to 10.0
    times = sent_at(line, "d1", read_telegram(1, 1613), before)
    assert len(times) == math.ceil((10.0 - 3.0) / every)
    on_time(times, 3.0, every)  # at its old due time, then the new interval
    on_time(sent_at(line, "d1", read_telegram(1, 1614), before), 3.0, 1.0)
    on_time(sent_at(line, "d2", read_telegram(2, 1613), before), 3.0, 1.0)
    assert len(sent_at(line, "d2", read_telegram(2, 1613), before)) == 7
    assert not [e for e in line.events if isinstance(e, Overrun)]


def test_a_new_interval_of_a_poll_on_the_wire_counts_from_its_next_due_time() -> None:
    line = line_of([1], [1], [1613], 1.0)
    line.run(2.5)
    send = hold(line, "d1")
    assert line.now == 3.0
    (kept,) = line.planner.drive("d1").spec.polls
    update_polls(line.planner, "d1", (dataclasses.replace(kept, every=2.0),), line.now)
    answer(line, send)
    before = len(line.sent)
    line.run(6.0)  # to 9.0 and a little
    on_time(sent_at(line, "d1", read_telegram(1, 1613), before), 5.0, 2.0)
    assert len(sent_at(line, "d1", read_telegram(1, 1613), before)) == 3  # 5, 7, 9


def test_a_new_poll_is_due_at_once() -> None:
    line = line_of([1, 2], [1, 2], [1613], 1.0)
    line.run(2.5)
    added = line.now
    polls = (*line.planner.drive("d1").spec.polls, poll(1, 1530, 1.0))
    assert update_polls(line.planner, "d1", polls, line.now) == list(polls)
    before = len(line.sent)
    line.run(5.0)
    assert line.sent[before].telegram == read_telegram(1, 1530)
    assert line.times[before] == added
    on_time(sent_at(line, "d1", read_telegram(1, 1530), before), added, 1.0)
    on_time(sent_at(line, "d1", read_telegram(1, 1613), before), 3.0, 1.0)
    on_time(sent_at(line, "d2", read_telegram(2, 1613), before), 3.0, 1.0)
    assert len(sent_at(line, "d1", read_telegram(1, 1530), before)) == 5


def test_a_removed_poll_is_never_sent_again() -> None:
    line = line_of([1, 2], [1, 2], [1613, 1614], 1.0)
    line.run(2.5)
    (_, kept) = line.planner.drive("d1").spec.polls
    assert update_polls(line.planner, "d1", (kept,), line.now) == [kept]
    before, events = len(line.sent), len(line.events)
    line.run(5.0)
    assert sent_at(line, "d1", read_telegram(1, 1613), before) == []
    assert not polled_since(line, "d1", 1613, events)
    on_time(sent_at(line, "d1", read_telegram(1, 1614), before), 3.0, 1.0)
    on_time(sent_at(line, "d2", read_telegram(2, 1613), before), 3.0, 1.0)
    assert len(sent_at(line, "d2", read_telegram(2, 1613), before)) == 5


def test_a_poll_removed_while_on_the_wire_ends_at_its_result_and_is_not_sent_again() -> None:
    line = line_of([1, 2], [1, 2], [1613, 1614], 1.0)
    line.run(2.5)
    send = hold(line, "d1", read_telegram(1, 1613))
    (_, kept) = line.planner.drive("d1").spec.polls
    update_polls(line.planner, "d1", (kept,), line.now)
    events = len(line.events)
    answer(line, send)
    (ended,) = [e for e in line.events[events:] if isinstance(e, Finished)]
    assert ended.drive == "d1" and isinstance(ended.work, PollSpec)
    assert ended.work.request.pnu == 1613 and isinstance(ended.outcome, Answered)
    before, events = len(line.sent), len(line.events)
    line.run(5.0)
    assert sent_at(line, "d1", read_telegram(1, 1613), before) == []
    assert not polled_since(line, "d1", 1613, events)
    assert len(sent_at(line, "d1", read_telegram(1, 1614), before)) >= 4
    assert len(sent_at(line, "d2", read_telegram(2, 1613), before)) >= 4


def test_a_poll_whose_request_changes_is_a_new_poll() -> None:
    """The same parameter label, another request: the old request is not sent again, the new
    one is due at once."""
    line = line_of([1], [1], [1613], 1.0)
    line.run(2.5)
    (old,) = line.planner.drive("d1").spec.polls
    new = dataclasses.replace(old, request=pkw.read(dialect_of(1), 1614))
    update_polls(line.planner, "d1", (new,), line.now)
    before = len(line.sent)
    line.run(3.0)
    assert sent_at(line, "d1", read_telegram(1, 1613), before) == []
    on_time(sent_at(line, "d1", read_telegram(1, 1614), before), 2.5, 1.0)


def test_a_new_poll_of_a_described_parameter_is_decoded_as_described_at_once() -> None:
    fake = describing_line()
    drive = fake.sim.drives[1]
    drive.params.specs[CURRENT] = dataclasses.replace(drive.params.specs[CURRENT], conversion=-3)
    fake.run(1.0)
    assert [e for e in fake.events if isinstance(e, Described) and e.drive == "d1"]
    (configured,) = fake.planner.drive("d1").spec.polls
    extra = dataclasses.replace(configured, parameter="16-14 again")
    events = len(fake.events)
    specs = update_polls(fake.planner, "d1", (configured, extra), fake.now)
    fake._collect()
    assert [p.fmt.scaling.factor for p in specs] == [Fraction(1, 1000)] * 2
    told = [e for e in fake.events[events:] if isinstance(e, Described)]
    assert len(told) == 1 and isinstance(told[0], Redecoded) and told[0].polls == (specs[1],)
    assert told[0].drive == "d1"
    at = fake.now
    while not [e for e in fake.events[events:] if isinstance(e, Finished) and e.work == specs[1]]:
        fake.step(at + 1.0)
    assert fake.now <= at + 4 * EXCHANGE, "due at once: after the polls due with it at most"
    fake.run(1.0)
    again = [p for p in polls_of(fake, "d1") if p.work == specs[1]]
    assert again and all(isinstance(p.outcome, Answered) for p in again)


def test_a_new_poll_waits_for_its_parameters_description() -> None:
    fake = describing_line()
    drive = fake.sim.drives[1]
    drive.params.specs[CURRENT] = dataclasses.replace(drive.params.specs[CURRENT], conversion=-3)
    (configured,) = fake.planner.drive("d1").spec.polls
    extra = dataclasses.replace(configured, parameter="16-14 again")
    update_polls(fake.planner, "d1", (configured, extra), fake.now)
    fake.run(1.0)
    (described,) = [e for e in fake.events if isinstance(e, Described) and e.drive == "d1"]
    assert {p.parameter for p in described.polls} == {"16-14", "16-14 again"}
    polls = polls_of(fake, "d1")
    assert {p.work.parameter for p in polls if isinstance(p.work, PollSpec)} == {
        "16-14",
        "16-14 again",
    }
    at = fake.events.index(described)
    assert all(fake.events.index(p) > at for p in polls), "no value before its description"
    assert {p.work.fmt.scaling.factor for p in polls if isinstance(p.work, PollSpec)} == {
        Fraction(1, 1000)
    }


# ---------------------------------------------------------------- a property

POLLED = (1613, 1614, 1610)  # the polls' parameters; jobs read 1530 and write 341
EVERY = (0.05, 0.2, 1.0)
ADDRESSES = (1, 2, 3, 4)
TELEGRAMS = {read_telegram(a, p): p for a in ADDRESSES for p in POLLED}

POLLS = st.dictionaries(st.sampled_from(POLLED), st.sampled_from(EVERY), max_size=3)
ADDRESS = st.sampled_from(ADDRESSES)
OPS = st.lists(
    st.one_of(
        st.tuples(st.just("run"), st.integers(0, 400)),
        st.tuples(st.just("add"), ADDRESS, POLLS),
        st.tuples(st.just("remove"), ADDRESS, st.booleans()),
        st.tuples(st.just("polls"), ADDRESS, POLLS, st.booleans()),
        st.tuples(st.just("submit"), ADDRESS, st.booleans()),
    ),
    max_size=30,
)


@dataclass
class CheckedLine(FakeLine):
    """A fake line that checks each telegram as it goes out against the configuration."""

    polled: dict[str, dict[int, float]] = field(default_factory=dict)
    held: Send | None = None  # the exchange on the wire while the line is reconfigured

    def check(self, send: Send) -> None:
        assert send.drive in self.polled, f"{send.drive} is not on the line"
        assert send.address == SerialCarrier(DriveTarget.create("fc", int(send.drive[1:]))).address
        pnu = TELEGRAMS.get(send.telegram)
        assert pnu is None or pnu in self.polled[send.drive], f"{pnu} is not polled"

    def answer(self, send: Send) -> ExchangeResult:
        if send is not self.held:  # that one was checked as it went out
            self.check(send)
        return super().answer(send)


def specs_of(address: int, polls: dict[int, float]) -> tuple[PollSpec, ...]:
    return tuple(poll(address, pnu, every) for pnu, every in sorted(polls.items()))


@settings(max_examples=300)
@given(ops=OPS)
def test_a_reloaded_line_sends_only_what_its_configuration_says(
    ops: list[tuple[object, ...]],
) -> None:
    """Over any run of additions, removals (with an exchange of the drive on the wire or
    not), poll updates and jobs: no telegram goes to a drive that is not on the line or
    for a poll it does not have; the drive's exchange on the wire is accepted; every poll
    configured is sent within its interval at the end; every job ends exactly once."""
    reload_run(ops)


def reload_run(ops: list[tuple[object, ...]]) -> None:
    initial = {1: {1613: 0.05}, 2: {1614: 0.2, 1610: 1.0}}
    sim = Simulator("fc", list(ADDRESSES), timing=SimTiming(response_delay=0.0), seed=7)
    planner = Planner(
        [dataclasses.replace(drives("fc", [a], [], 1.0)[0], polls=specs_of(a, p))
         for a, p in initial.items()],
        poll_deadline=0.5,
    )  # fmt: skip
    line = CheckedLine(planner, sim, polled={f"d{a}": dict(p) for a, p in initial.items()})
    jobs: list[Job] = []

    def held(address: int, hold_it: object) -> Send | None:
        """The drive's next exchange, out on the wire (None: not asked, or none comes)."""
        if not hold_it:
            return None
        send = hold_if(line, f"d{address}", within=2.0)
        if send is not None:
            line.check(send)
        line.held = send
        return send

    for op in ops:
        name = f"d{op[1]}" if op[0] != "run" else ""
        if op[0] == "run":
            line.run(int(op[1]) * MS)  # type: ignore[call-overload]
        elif op[0] == "add":
            if name in line.polled:
                continue
            address, polls = int(op[1]), dict(op[2])  # type: ignore[call-overload]
            spec = dataclasses.replace(
                drives("fc", [address], [], 1.0)[0], polls=specs_of(address, polls)
            )
            planner.add_drive(spec, line.now)
            line.polled[name] = polls
        elif op[0] == "remove":
            if name not in line.polled:
                continue
            send = held(int(op[1]), op[2])  # type: ignore[call-overload]
            planner.remove_drive(name, REASON, line.now)
            del line.polled[name]
            if send is not None:
                answer(line, send)
        elif op[0] == "polls":
            if name not in line.polled:
                continue
            address, polls = int(op[1]), dict(op[2])  # type: ignore[call-overload]
            send = held(address, op[3])
            specs = specs_of(address, polls)
            assert update_polls(planner, name, specs, line.now) == list(specs)
            line.polled[name] = polls
            if send is not None:
                answer(line, send)
        else:
            if name not in line.polled:
                continue
            dialect = dialect_of(int(op[1]))  # type: ignore[call-overload]
            is_write = bool(op[2])
            request = (
                pkw.write(dialect, 341, 5, pkw.Width.DWORD) if is_write
                else pkw.read(dialect, 1530)
            )  # fmt: skip
            jobs.append(job(line, name, request, Priority.WRITE if is_write else Priority.READ))
        line.held = None
        line._collect()
        assert planner._roster.leaving == {}, "a removed drive whose result came is forgotten"
    before = len(line.sent)
    line.run(max(EVERY) + 0.5)
    for name, polls in line.polled.items():
        for pnu in polls:
            assert sent_at(line, name, read_telegram(int(name[1:]), pnu), before), (name, pnu)
    planner.stop("stopping")
    line._collect()
    for queued in jobs:
        assert len(line.finished(queued)) == 1, "every job ends exactly once"


def test_a_drive_added_after_one_that_left_lost_its_port_is_polled() -> None:
    """A drive removed with its exchange out, the port lost before that exchange's result,
    then a drive of the same name added: the loss ended the old exchange, so the new drive's
    first result is its own (it is polled on, not left busy)."""
    line = line_of([1, 2], [1, 2], [1613], 100 * MS)
    hold(line, "d2")  # d2's poll on the wire
    line.planner.remove_drive("d2", REASON, line.now)
    line.planner.line_down(line.now)  # the port fails before the answer
    line.now += 1.0
    line.planner.line_up(line.now)
    (spec,) = drives("fc", [2], [1613], 0.1)
    line.planner.add_drive(spec, line.now)
    start = line.now
    line.run(2.0)
    polled = [
        t for s, t in zip(line.sent, line.times, strict=True) if s.drive == "d2" and t > start
    ]
    assert len(polled) >= 10  # every 100 ms for 2 s, give or take the other drive's turns
    assert not line.planner.drive("d2").busy or line.planner.drive("d2").active is not None
