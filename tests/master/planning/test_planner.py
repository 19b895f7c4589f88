"""The planner's policy on a fake clock: no port, no sleeping, every time in milliseconds.

A fake line asks the planner for its next action, lets the simulator's drives
answer (or not) at a fake time, and feeds the result back. The same policy
runs the service's lines and the command line's single jobs.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections import Counter
from dataclasses import dataclass, field

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.master.carriers import SerialCarrier, carrier_for
from pkwbus.master.planning.answers import ErrorKind, ExchangeResult, Failure, Reply
from pkwbus.master.planning.drive import DrivePlan
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.jobs import Cancelled, Job, JobKind, Priority
from pkwbus.master.planning.outcomes import Answered, LineFailed, TimedOut
from pkwbus.master.planning.plan import (
    DriveSpec,
    Event,
    Finished,
    HealthChanged,
    Idle,
    Overrun,
    PollSpec,
    Send,
    StatusWord,
)
from pkwbus.master.planning.planner import Planner
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.serial.telegram import Telegram
from pkwbus.sim import SimFaults, SimTiming, Simulator

MS = 0.001
TIMEOUT = 30 * MS  # what a missing answer costs the fake line
EXCHANGE = 2 * MS  # what an answered exchange costs


def drives(protocol: str, addresses: list[int], pnus: list[int], every: float) -> list[DriveSpec]:
    specs = []
    for a in addresses:
        target = DriveTarget.create(protocol, a)
        polls = tuple(PollSpec(str(p), 0, pkw.read(target.dialect, p), every) for p in pnus)
        specs.append(DriveSpec(f"d{a}", carrier_for(target), polls))
    return specs


def target_of(planner: Planner, drive: str) -> SerialCarrier:
    """A serial drive's carrier, which builds its requests as they go out now."""
    carrier = planner.drive(drive).carrier
    assert isinstance(carrier, SerialCarrier)
    return carrier


@dataclass
class FakeLine:
    """A line on a fake clock: the simulator answers, a dead drive costs a timeout."""

    planner: Planner
    sim: Simulator
    now: float = 0.0
    sent: list[Send] = field(default_factory=list)
    results: list[ExchangeResult] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)
    times: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.planner.line_up(self.now)

    def answer(self, send: Send) -> ExchangeResult:
        request = next(
            (e for e in self.sim.deframer().feed(send.telegram) if isinstance(e, Telegram)), None
        )  # None: a length the simulated drives do not take (a fixed PKW length)
        answer = None if request is None else self.sim.answer(request, self.now)
        if answer is None:
            self.now += TIMEOUT
            return Failure(ErrorKind.TIMEOUT, "no answer")
        self.now += EXCHANGE
        reply = next(e for e in self.sim.deframer().feed(answer.data) if isinstance(e, Telegram))
        return Reply(reply.adr, reply.data, EXCHANGE)

    def step(self, until: float) -> Send | None:
        action = self.planner.next_action(self.now)
        if isinstance(action, Idle):
            self.now = max(self.now, min(action.until, until))
            self._collect()
            return None
        self.times.append(self.now)
        result = self.answer(action)
        self.sent.append(action)
        self.results.append(result)
        self.planner.exchanged(action, result, self.now)
        self._collect()
        return action

    def run(self, seconds: float) -> None:
        end = self.now + seconds
        while self.now < end:
            self.step(end)

    def submit(self, drive: str, request: pkw.PkwRequest, *, within: float = 2.0) -> Job:
        kind = JobKind.WRITE if request.is_write else JobKind.READ
        prio = Priority.WRITE if request.is_write else Priority.READ
        job = Job(drive, request, kind, prio, self.now + within)
        self.planner.submit(job, self.now)
        self._collect()
        return job

    def _collect(self) -> None:
        self.events.extend(self.planner.take_events())

    # ------------------------------------------------------------ reading

    def polls_ok(self, drive: str) -> int:
        return sum(
            1
            for e in self.events
            if isinstance(e, Finished)
            and e.drive == drive
            and isinstance(e.work, PollSpec)
            and isinstance(e.outcome, Answered)
        )

    def finished(self, job: Job) -> list[Finished]:
        return [e for e in self.events if isinstance(e, Finished) and e.work is job]

    def shown(self, drive: str) -> bool:
        changes = [e.up for e in self.events if isinstance(e, HealthChanged) and e.drive == drive]
        return changes[-1] if changes else True


def fake_line(
    protocol: str,
    addresses: list[int],
    pnus: list[int],
    every: float,
    *,
    timing: SimTiming | None = None,
    faults: SimFaults | None = None,
    policy: HealthPolicy | None = None,
    retries: int = 2,
) -> FakeLine:
    sim = Simulator(
        protocol, addresses, timing=timing or SimTiming(response_delay=0.0), faults=faults, seed=7
    )
    specs = drives(protocol, addresses, pnus, every)
    planner = Planner(specs, poll_deadline=0.5, retries=retries, policy=policy)
    return FakeLine(planner, sim)


# ------------------------------------------------------------------ examples


def test_polls_carry_the_drives_values_and_status_words() -> None:
    line = fake_line("fc", [1, 2], [341, 1530], 50 * MS)
    line.run(1.0)
    for a in (1, 2):
        assert line.polls_ok(f"d{a}") >= 2 * 20 - 2  # two parameters every 50 ms
        values = [
            e.outcome.response
            for e in line.events
            if isinstance(e, Finished) and e.drive == f"d{a}" and isinstance(e.outcome, Answered)
        ]
        assert all(isinstance(v, pkw.ValueResponse) for v in values)
    words = {e.drive: e.word for e in line.events if isinstance(e, StatusWord)}
    assert words["d1"] == line.sim.drives[1].status_word


def test_a_reply_that_is_no_block_tells_no_status_word() -> None:
    """The status word (and main actual value) of an earlier reply is never told again as
    if a later reply that could not be split had carried it."""
    line = fake_line("fc", [1], [341], 50 * MS)
    send = line.planner.next_action(line.now)
    assert isinstance(send, Send)
    # The drive answers another parameter: "not yet", with its status word.
    target = target_of(line.planner, send.drive)
    other = target.telegram(pkw.read(target.dialect, 1530))
    not_ours = line.answer(dataclasses.replace(send, telegram=other))
    assert isinstance(not_ours, Reply)
    line.planner.exchanged(send, not_ours, line.now)
    told = [e for e in line.planner.take_events() if isinstance(e, StatusWord)]
    assert [e.word for e in told] == [line.sim.drives[1].status_word]
    # The repeat's answer is no block of this drive's shape: an unexpected answer.
    again = line.planner.next_action(line.now)
    assert again == send
    line.planner.exchanged(send, Reply(1, b"\x01\x02\x03", EXCHANGE), line.now)
    assert not [e for e in line.planner.take_events() if isinstance(e, StatusWord)]


def test_writes_then_reads_then_polls_after_the_exchange_in_flight() -> None:
    line = fake_line("fc", [1, 2, 3], [1613, 1614, 1610], MS)  # polls always due
    line.run(0.2)
    dialect = line.planner.drives[0].carrier.target.dialect
    read = line.submit("d3", pkw.read(dialect, 1530))
    write = line.submit("d2", pkw.write(dialect, 341, 777, pkw.Width.DWORD))
    before = len(line.sent)
    line.run(0.05)
    order = [s.telegram for s in line.sent[before : before + 3]]
    assert order == [  # a change goes out after a read of its parameter (write_gate)
        line.planner.drives[1].carrier.telegram(pkw.read(dialect, 341)),
        line.planner.drives[1].carrier.telegram(write.request),
        line.planner.drives[2].carrier.telegram(read.request),
    ]
    assert isinstance(line.finished(write)[0].outcome, Answered)
    assert line.sim.drives[2].value(341) == 777


def test_drives_share_the_line_fairly() -> None:
    line = fake_line("fc", [1, 2, 3, 4], [1613], 0.0)  # every poll due at once, always
    line.run(1.0)
    counts = Counter(s.drive for s in line.sent)
    assert max(counts.values()) - min(counts.values()) <= 1
    # round robin: no drive twice before every other one had its turn
    names = [s.drive for s in line.sent]
    for i in range(0, len(names) - 4, 4):
        assert len(set(names[i : i + 4])) == 4


def test_a_dead_drive_costs_the_others_almost_nothing() -> None:
    rates = []
    for dead in (frozenset(), frozenset({4})):
        line = fake_line(
            "fc", [1, 2, 3, 4], [1613, 1614], 50 * MS, faults=SimFaults(dead=dead),
            policy=HealthPolicy(down_after=3, probe_initial=1.0, probe_cap=4.0),
        )  # fmt: skip
        line.run(10.0)
        rates.append(sum(line.polls_ok(f"d{a}") for a in (1, 2, 3)))
        if dead:
            assert not line.shown("d4")
            probes = [t for s, t in zip(line.sent, line.times, strict=True) if s.probe]
            gaps = [b - a for a, b in itertools.pairwise(probes)]
            # capped exponential back-off, each probe at most one exchange late
            for gap, expected in zip(gaps, [2.0, 4.0, 4.0], strict=False):
                assert expected <= gap < expected + TIMEOUT + EXCHANGE
    healthy, with_dead = rates
    assert with_dead >= 0.98 * healthy


def test_a_drive_that_comes_back_is_polled_again_without_overruns() -> None:
    policy = HealthPolicy(down_after=2, probe_initial=0.2, probe_cap=0.4)
    line = fake_line(
        "fc", [1, 2], [1613], 20 * MS, faults=SimFaults(dead=frozenset({2})), policy=policy
    )
    line.run(0.5)
    assert not line.shown("d2")
    line.sim.revive(2)
    line.run(0.45)  # one probe interval (cap 0.4 s)
    assert line.shown("d2")
    assert line.polls_ok("d2") >= 1
    assert not [e for e in line.events if isinstance(e, Overrun) and e.drive == "d2"]


def test_overruns_are_counted_when_polls_exceed_the_line() -> None:
    line = fake_line("fc", [1, 2], [1613, 1614, 1610, 1630, 1690], 5 * MS)  # 10 per 5 ms
    line.run(0.5)
    overruns = Counter(e.drive for e in line.events if isinstance(e, Overrun))
    assert overruns["d1"] > 0 and overruns["d2"] > 0


def test_a_lagging_drive_yields_between_its_repeats() -> None:
    timing = SimTiming(response_delay=0.0, lag_telegrams=3, lag_mode="none")
    line = fake_line("uss", [1, 2, 3], [1120, 1121], MS, timing=timing)
    line.run(0.5)
    names = [s.drive for s in line.sent]
    assert not [a for a, b in itertools.pairwise(names) if a == b], "a repeat went back to back"
    assert all(line.polls_ok(f"d{a}") > 0 for a in (1, 2, 3))


def test_a_dying_drives_retries_let_the_others_in_between() -> None:
    line = fake_line("fc", [1, 2, 3], [1613], 5 * MS)
    line.run(0.2)
    line.sim.kill(3)
    line.run(0.4)
    failed = [i for i, r in enumerate(line.results) if isinstance(r, Failure)]
    assert len(failed) >= 3  # retries, then down
    assert all(line.sent[i].drive == "d3" for i in failed)
    assert all(line.sent[i + 1].drive != "d3" for i in failed[:3] if i + 1 < len(line.sent))
    assert not line.shown("d3")
    ended = [e for e in line.events if isinstance(e, Finished) and e.drive == "d3"]
    assert isinstance(ended[-1].outcome, TimedOut)  # its poll in flight ended


def test_a_job_that_waits_past_its_deadline_ends_unsent() -> None:
    timing = SimTiming(response_delay=0.0, lag_telegrams=1000, lag_mode="none")
    line = fake_line("uss", [1], [], 1.0, timing=timing)
    dialect = line.planner.drives[0].carrier.target.dialect
    first = line.submit("d1", pkw.read(dialect, 1120), within=0.3)
    second = line.submit("d1", pkw.read(dialect, 1121), within=0.1)
    line.run(0.5)
    assert isinstance(line.finished(first)[0].outcome, TimedOut)  # lagged to its deadline
    (ended,) = line.finished(second)
    assert isinstance(ended.outcome, TimedOut) and ended.tally is None  # never sent
    assert all(
        s.telegram != line.planner.drives[0].carrier.telegram(second.request) for s in line.sent
    )
    assert line.now - 0.5 < TIMEOUT and all(t < 0.3 for t in line.times)  # never past its deadline


def test_a_port_outage_fails_jobs_and_shows_drives_down() -> None:
    timing = SimTiming(response_delay=0.0, lag_telegrams=1000, lag_mode="none")
    line = fake_line("uss", [1, 2], [1120], 50 * MS, timing=timing)
    line.run(0.2)
    dialect = line.planner.drives[0].carrier.target.dialect
    write = line.submit("d1", pkw.write(dialect, 1121, 0x41200000, pkw.Width.DWORD), within=30)
    line.run(0.2)
    assert not line.finished(write)  # it lags: in flight, repeated
    line.planner.port_failed()
    line.planner.line_down(line.now)
    line._collect()
    assert isinstance(line.finished(write)[0].outcome, LineFailed)
    assert not line.shown("d1") and not line.shown("d2")
    late = line.submit("d2", pkw.read(dialect, 1120))
    assert isinstance(line.finished(late)[0].outcome, LineFailed)  # nothing waits for the port
    assert isinstance(line.planner.next_action(line.now), Idle)
    before = len(line.sent)
    line.planner.line_up(line.now)
    line.run(0.3)
    assert write.request not in [s.telegram for s in line.sent[before:]]
    telegram = line.planner.drives[0].carrier.telegram(write.request)
    assert telegram not in [s.telegram for s in line.sent[before:]]
    assert line.shown("d1") and line.shown("d2")


def test_stop_cancels_queued_and_running_jobs() -> None:
    timing = SimTiming(response_delay=0.0, lag_telegrams=1000, lag_mode="none")
    line = fake_line("uss", [1], [1120], 1.0, timing=timing)
    dialect = line.planner.drives[0].carrier.target.dialect
    jobs = [line.submit("d1", pkw.read(dialect, 1121)) for _ in range(3)]
    line.run(0.1)
    line.planner.stop("the service is stopping")
    line._collect()
    assert all(isinstance(line.finished(j)[0].outcome, Cancelled) for j in jobs)
    assert all(len(line.finished(j)) == 1 for j in jobs)
    late = line.submit("d1", pkw.read(dialect, 1121))
    assert isinstance(line.finished(late)[0].outcome, Cancelled)


def test_one_job_per_slot_on_a_cyclic_line() -> None:
    """A PROFIBUS DP line: a slave's PKW slot carries one job at a time, by the same priorities."""
    line = fake_line("fc", [1, 2], [1613], 10 * MS)
    planner = line.planner
    for d in planner.drives:  # as a DP slot's carrier: it waits for AK 0 before a job
        d.carrier.repeats_answers = False  # type: ignore[misc]
    dialect = planner.drives[0].carrier.target.dialect
    write = line.submit("d1", pkw.write(dialect, 341, 5, pkw.Width.DWORD))
    read = line.submit("d1", pkw.read(dialect, 1530))
    cycle: list[Send | None] = [planner.next_for(d, line.now) for d in ("d1", "d2")]
    assert [s.telegram if s else None for s in cycle] == [
        planner.drives[0].carrier.telegram(write.request),
        planner.drives[1].carrier.telegram(pkw.read(dialect, 1613)),
    ]
    assert planner.next_for("d1", line.now) is None  # its slot is taken until the result
    for send in cycle:
        assert send is not None
        planner.exchanged(send, line.answer(send), line.now)
    nxt = planner.next_for("d1", line.now)
    assert nxt is not None and nxt.telegram == planner.drives[0].carrier.telegram(read.request)


def test_an_exchange_costs_the_same_with_thousands_of_drives(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Drives wait in heaps: the planner looks at a few of them per exchange, not all."""
    looked = Counter[int]()
    claim = DrivePlan.claim
    size = [0]

    def counting(self: DrivePlan, now: float, events: list[object]) -> object:
        looked[size[0]] += 1
        return claim(self, now, events)  # type: ignore[arg-type]

    monkeypatch.setattr(DrivePlan, "claim", counting)
    per_exchange = {}
    for n in (10, 2000):
        size[0] = n
        line = fake_line("fc", list(range(1, 127))[: min(n, 126)], [1613], 0.0)
        specs = drives("fc", [1] * n, [1613], 1000.0)
        specs = [DriveSpec(f"x{i}", s.carrier, s.polls) for i, s in enumerate(specs)]
        planner = Planner(specs, poll_deadline=0.5)
        line = FakeLine(planner, line.sim)
        line.run(0.0)
        start = looked[n]
        line.run(0.5)
        per_exchange[n] = (looked[n] - start) / len(line.sent)
    assert per_exchange[2000] <= per_exchange[10] + 1


# ---------------------------------------------------------------- properties


def priority_sent(planner: Planner, send: Send) -> Priority:
    active = planner._by_name[send.drive].active
    return Priority.POLL if send.probe or active is None else active.priority


def pending(planner: Planner) -> list[Priority]:
    """What waits on the other drives: a job in flight, queued writes, queued reads."""
    found = []
    for d in planner.drives:
        if d.busy:
            continue
        if d.active is not None:
            found.append(d.active.priority)
        elif d.writes or d.reads:
            found.append(Priority.WRITE if d.writes else Priority.READ)
    return found


OPS = st.lists(
    st.one_of(
        st.tuples(st.just("step"), st.sampled_from(["answer", "timeout", "checksum"])),
        st.tuples(st.just("wait"), st.integers(0, 300)),
        st.tuples(st.just("submit"), st.integers(0, 2), st.booleans(), st.integers(1, 400)),
        st.tuples(st.just("outage"), st.integers(0, 500)),
    ),
    max_size=60,
)


@settings(max_examples=120, deadline=None)
@given(ops=OPS, every=st.sampled_from([0.0, 5 * MS, 50 * MS]))
def test_the_heap_chooses_what_the_policy_says(ops: list[tuple[object, ...]], every: float) -> None:
    line = fake_line("fc", [1, 2, 3], [1613, 1614], every, policy=HealthPolicy(2, 0.05, 0.2))
    planner = line.planner
    dialect = planner.drives[0].carrier.target.dialect
    jobs: list[Job] = []
    current: dict[str, bytes] = {}
    for op in ops:
        if op[0] == "wait":
            line.now += int(op[1]) * MS  # type: ignore[call-overload]
        elif op[0] == "submit":
            _, drive, is_write, within = op
            request = (
                pkw.write(dialect, 341, 5, pkw.Width.DWORD) if is_write else pkw.read(dialect, 1530)
            )
            jobs.append(line.submit(f"d{drive + 1}", request, within=int(within) * MS))  # type: ignore[call-overload]
        elif op[0] == "outage":
            planner.port_failed()
            planner.line_down(line.now)
            line._collect()
            current.clear()
            line.now += int(op[1]) * MS  # type: ignore[call-overload]
            planner.line_up(line.now)
        else:
            # What the policy says, drive by drive, against the one the heaps give.
            claims = {d.name: d.claim(line.now, planner.events)[0] for d in planner.drives}
            before = len(line.events)
            action = planner.next_action(line.now)
            line._collect()
            ended = {e.drive for e in line.events[before:] if isinstance(e, Finished)}
            for drive in ended:
                current.pop(drive, None)
            live = [k for n, k in claims.items() if k is not None and n not in ended]
            if isinstance(action, Idle):
                assert not live
                line.now = max(line.now, min(action.until, line.now + 1.0))
                continue
            if action.drive not in ended:  # (a drive whose transaction ended has a new claim)
                assert claims[action.drive] == min(live)
            assert priority_sent(planner, action) <= min(pending(planner), default=Priority.POLL)
            if not action.probe:
                if action.drive in current:
                    # a change goes out after the read of its parameter, in the same job
                    target = target_of(planner, action.drive)
                    read_first = target.telegram(pkw.read(target.dialect, 341))
                    went_on = current[action.drive] in (action.telegram, read_first)
                    assert went_on, "one transaction at a time"
                current[action.drive] = action.telegram
            result: ExchangeResult
            if op[1] == "answer":
                result = line.answer(action)
            else:
                result = Failure(ErrorKind(op[1]), "")
                line.now += TIMEOUT
            line.sent.append(action)
            line.times.append(line.now)
            before = len(line.events)
            planner.exchanged(action, result, line.now)
            line._collect()
            for e in line.events[before:]:
                if isinstance(e, Finished):
                    current.pop(e.drive, None)
    planner.stop("stopping")
    line._collect()
    for job in jobs:
        assert len(line.finished(job)) == 1, "every job ends exactly once"
