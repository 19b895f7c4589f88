"""A drive as the planner sees it: its queues, its transaction in flight, its polls, its health."""

from __future__ import annotations

import heapq
import itertools
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

from pkwbus.master.planning.agenda import Key
from pkwbus.master.planning.answers import ExchangeResult
from pkwbus.master.planning.carrier import Item, Transaction
from pkwbus.master.planning.describing import DescribeStep, DriveDescriber, Settled, described_poll
from pkwbus.master.planning.health import DriveHealth, HealthPolicy
from pkwbus.master.planning.identity import identity_requests
from pkwbus.master.planning.jobs import Job, Priority, ProbeJob
from pkwbus.master.planning.outcomes import NotSent, Outcome, TimedOut
from pkwbus.master.planning.plan import (
    Described,
    DescribedAnew,
    DescribedFromBook,
    DescriptionSettled,
    DriveSpec,
    Event,
    Finished,
    Forgotten,
    LeftUnanswered,
    Overrun,
    PkwLengthTold,
    PollBatch,
    PollState,
    Send,
    StatusWord,
    polls_of,
)
from pkwbus.master.planning.transaction import PkwTransaction, ProbeTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.length import PkwLength

__all__ = ["Active", "DrivePlan", "Work", "expire"]


# A queued job, a poll, a description's element, or polls in one request.
Work = Job | ProbeJob | PollState | DescribeStep | PollBatch


@dataclass(eq=False, slots=True)
class Active:
    """A drive's transaction in flight: a queued job's, a poll's, or (data record 47) the
    polls due together."""

    tx: Transaction
    priority: Priority
    order: float
    work: Work
    send: Send
    # The read of a change's parameter before the change (master.write_gate).
    read_first: bool = False


class DrivePlan:
    __slots__ = (
        "active",
        "background",
        "busy",
        "carrier",
        "describer",
        "health",
        "held",
        "lagging",
        "last_answer",
        "maintenance",
        "name",
        "polls",
        "reads",
        "seq",
        "served",
        "shown_up",
        "slot",
        "spec",
        "version",
        "writes",
    )  # fmt: skip

    def __init__(self, spec: DriveSpec, policy: HealthPolicy, slot: int, count: int) -> None:
        self.spec = spec
        self.name = spec.name
        self.carrier = carrier = spec.carrier
        self.slot = slot
        self.served = slot - count  # never served yet: in configuration order
        self.version = 0
        self.busy = False  # its exchange is out: not in the ready heap
        if carrier.tells_health:  # the wire tells it: missing answers never take it down
            policy = replace(policy, from_answers=False)
        self.health = DriveHealth(policy)
        # A DP slave is down until its wire tells it is in data exchange; others are up
        # until they fail.
        self.shown_up = not carrier.tells_health
        self.maintenance = False  # in maintenance: nothing goes out to it
        self.writes: deque[Job] = deque()
        self.reads: deque[Job | ProbeJob] = deque()
        self.background: deque[Job] = deque()  # after its due polls
        self.active: Active | None = None
        self.lagging = False
        self.seq = itertools.count()
        self.polls: list[tuple[float, int, PollState]] = []
        self.describer: DriveDescriber | None = None
        if spec.form is not None and spec.describe:
            wanted = ((t.pnu, t.elements) for t in spec.describe)
            dialect = carrier.dialect
            self.describer = DriveDescriber(
                dialect, spec.form, wanted, book=spec.book,
                identity=identity_requests(dialect, texts=carrier.texts),
            )  # fmt: skip
        # Polls waiting for their parameter's description, by PNU.
        self.held: dict[int, list[PollState]] = {}
        for p in spec.polls:
            if self.describer is not None and self.describer.waiting(p.request.pnu):
                self.held.setdefault(p.request.pnu, []).append(PollState(p, 0.0))
            else:
                self.push_poll(PollState(p, 0.0))
        self.last_answer: bytes | None = None  # PKW bytes of its latest answer (not AK 0)

    def claim(self, now: float, events: list[Event]) -> tuple[Key | None, float | None]:
        """Its claim on the line's next exchange, and when it will have a better one: a
        background claim's next poll, or the first claim of a drive without one. Queued
        jobs past their deadline end first (their events into ``events``)."""
        if self.maintenance:
            return None, None
        if self.writes or self.reads or self.background:  # most often none is queued
            for queue in (self.writes, self.reads, self.background):
                if queue:
                    events += expire(self, queue, now)
        a, served, slot = self.active, self.served, self.slot
        if a is not None:
            return (a.priority, int(self.lagging), a.order, served, slot), None
        if self.writes:
            return (Priority.WRITE, 0, self.writes[0].deadline, served, slot), None
        if self.reads:
            return (Priority.READ, 0, self.reads[0].deadline, served, slot), None
        if not self.health.up:
            if self.health.probe_due(now):
                return (Priority.POLL, 0, self.health.next_probe, served, slot), None
            return None, self.health.next_probe
        due = self.first_due()
        if due is not None and due <= now:
            return (Priority.POLL, 0, due, served, slot), None
        if self.background:
            return (Priority.BACKGROUND, 0, self.background[0].deadline, served, slot), due
        return None, due

    def transaction(
        self, items: Sequence[Item], *, retries: int, deadline: float, stale: bytes | None = None
    ) -> Transaction:
        """One PKW job, or where its carrier takes several, one request of all ``items``;
        LocalProtocolError for what the drive's carrier cannot carry."""
        return self.carrier.transaction(items, retries=retries, deadline=deadline, stale=stale)

    def send_of(self, tx: Transaction) -> Send:
        """The exchange that carries ``tx``'s request."""
        return Send(self.name, self.carrier.address, tx.telegram)

    def next_probe(self) -> Send | None:
        """The probe of a down drive (None: its carrier never probes)."""
        probe = self.carrier.probe()
        if probe is None:
            return None
        return Send(self.name, self.carrier.address, probe.telegram, True, probe.words)

    def probe_job(self, job: ProbeJob, order: float, *, retries: int) -> Active | Finished:
        """The transaction of a probe job (:class:`Finished` when its carrier never probes)."""
        probe = self.carrier.probe()
        if probe is None:
            return Finished(self.name, job, NotSent("its bus tells whether it is there"))
        tx = ProbeTransaction(
            probe.telegram, self.carrier.status, retries=retries, deadline=job.deadline
        )
        send = Send(self.name, self.carrier.address, probe.telegram, True, probe.words)
        return Active(tx, job.priority, order, job, send)

    def probed(self, send: Send, result: ExchangeResult) -> PkwLengthTold | None:
        """A probe was answered: the event when it told how requests go out."""
        return self._told(self.carrier.probed(send.words, result))

    def heard(self, tx: PkwTransaction) -> PkwLengthTold | None:
        """Take what the answer ``tx`` just decoded tells; the event when the drive's PKW
        length, as known, changed (requests then go out with the new one)."""
        answer, response = tx.answer_pkw, tx.response
        if answer is None or response is None:
            return None
        if not isinstance(response, pkw.NoResponse):
            self.last_answer = answer
        return self._told(self.carrier.heard(tx))

    def forget_pkw(self) -> PkwLengthTold | None:
        """The drive went down: a learned PKW length is learned again when it answers."""
        return self._told(self.carrier.forget())

    def _told(self, length: PkwLength | None) -> PkwLengthTold | None:
        return PkwLengthTold(self.name, length) if length is not None else None

    def first_due(self) -> float | None:
        """When the drive's next poll or description request is due (None: never)."""
        due = self.polls[0][0] if self.polls else None
        ask = self.describer.due() if self.describer is not None else None
        if ask is not None and (due is None or ask <= due):
            return ask
        return due

    def start_poll(
        self, now: float, deadline: float, retries: int
    ) -> tuple[Active | None, list[Event]]:
        """The drive's next description request or due poll as a transaction in flight
        (None: nothing to send now), and the events of starting it (an overrun; parameters
        another drive of its kind described meanwhile)."""
        events: list[Event] = []
        describer = self.describer
        ask = describer.due() if describer is not None else None
        first = not self.polls or (ask is not None and self.polls[0][0] >= ask)  # no poll before
        if describer is not None and ask is not None and ask <= now and first:
            step = describer.next_request(now)
            events += self.settle(describer.take_ready(), now)
            if step is not None:
                tx = self.transaction([Item(step.request)], retries=retries, deadline=deadline)
                return Active(tx, Priority.POLL, now, step, self.send_of(tx)), events
        if not self.polls or self.polls[0][0] > now:
            return None, events
        if self.carrier.room(2):  # several parameters in one request: the polls due together
            return self._start_batch(now, deadline, retries, events)
        _, _, poll = heapq.heappop(self.polls)
        spec = poll.spec
        if now - poll.due > spec.every and not poll.fresh:
            events.append(Overrun(self.name))
        poll.fresh = False
        # Long enough for the retries and a lagging answer; never the poll's whole
        # interval, which would hold the drive's parameter channel for minutes.
        tx = self.transaction(spec.items, retries=retries, deadline=deadline)
        return Active(tx, Priority.POLL, poll.due, poll, self.send_of(tx)), events

    def _start_batch(
        self, now: float, deadline: float, retries: int, events: list[Event]
    ) -> tuple[Active | None, list[Event]]:
        """The polls due now, as many as one request of its carrier takes, together; with
        them those due within half the first one's interval, so that polls released at
        different times come to share their requests (a poll is never read later than due,
        only at times a little earlier)."""
        due: list[PollState] = []
        until = now + self.polls[0][2].spec.every / 2
        carrier = self.carrier
        while self.polls and self.polls[0][0] <= until and carrier.room(len(due) + 1):
            poll = heapq.heappop(self.polls)[2]
            if now - poll.due > poll.spec.every and not poll.fresh:
                events.append(Overrun(self.name))
            poll.fresh = False
            why = carrier.refuses(poll.spec.request)
            if why:  # a text, say: ended unsent, polled (and refused) again at its interval
                events.append(Finished(self.name, poll.spec, NotSent(why)))
                poll.due = now + poll.spec.every
                self.push_poll(poll)
                continue
            due.append(poll)
        if not due:
            return None, events
        items = [Item(p.spec.request, p.spec.fmt.vtype) for p in due]
        tx = self.transaction(items, retries=retries, deadline=deadline)
        batch = PollBatch(tuple(due))
        return Active(tx, Priority.POLL, due[0].due, batch, self.send_of(tx)), events

    @property
    def describing(self) -> bool:
        """Whether its exchange in flight is a description request (AK 4): some drives
        leave those unanswered and answer everything else."""
        work = self.active.work if self.active is not None else None
        return isinstance(work, DescribeStep) and not work.identity

    def went_down(self) -> PkwLengthTold | None:
        """The drive is down: another drive of its kind describes what it was describing;
        a learned PKW length is learned again when it answers."""
        if self.describer is not None:
            self.describer.release()
        return self.forget_pkw()

    def described(self, step: DescribeStep, outcome: Outcome, now: float) -> list[Described]:
        """What came of a description request; the parameters it settled."""
        describer = self.describer
        assert describer is not None  # it made the request
        settled = describer.took(step, outcome, now)
        forgotten: list[Described] = []
        if describer.changed:  # another drive now: its values wait for its description
            describer.changed = False
            self._hold_again()
            why = f"another drive now ({describer.identity})"
            forgotten = [
                Forgotten(self.name, t, why, describer.identity)
                for t in self.spec.describe
            ]  # fmt: skip
        return forgotten + self.settle(settled, now)

    def _hold_again(self) -> None:
        describer = self.describer
        assert describer is not None
        kept = []
        for entry in self.polls:
            poll = entry[2]
            if describer.waiting(poll.spec.request.pnu):
                self.held.setdefault(poll.spec.request.pnu, []).append(poll)
            else:
                kept.append(entry)
        self.polls[:] = kept
        heapq.heapify(self.polls)

    def settle(self, settled: list[Settled], now: float) -> list[DescriptionSettled]:
        """Parameters whose description settled: their polls, decoded as now described,
        go out from now on (those that waited are due now)."""
        events: list[DescriptionSettled] = []
        targets = {t.pnu: t for t in self.spec.describe}
        for done in settled:
            polls = self.held.pop(done.pnu, [])
            waiting = {id(p) for p in polls}
            polls += [e[2] for e in self.polls if e[2].spec.request.pnu == done.pnu]
            work = self.active.work if self.active is not None else None
            polls += [p for p in polls_of(work) if p.spec.request.pnu == done.pnu]
            for poll in polls:
                poll.spec = described_poll(poll.spec, done, self.carrier.dialect)
            untyped = done.description is None or done.description.vtype is None
            withheld = []
            for poll in polls:
                if id(poll) not in waiting:
                    continue
                if untyped and poll.spec.described_only:  # no type: it goes on waiting
                    self.held.setdefault(done.pnu, []).append(poll)
                    withheld.append(poll)
                    continue
                poll.due, poll.fresh = now, True
                self.push_poll(poll)
            specs = tuple(p.spec for p in polls if p not in withheld)
            state = (LeftUnanswered if done.unanswered
                     else DescribedFromBook if done.from_book else DescribedAnew)  # fmt: skip
            events.append(
                state(self.name, targets[done.pnu], done.description, specs, done.why,
                      done.first, done.identity, tuple(p.spec for p in withheld))
            )  # fmt: skip
        if any(e.polls for e in events):
            heapq.heapify(self.polls)
        return events

    def status_of(self, result: ExchangeResult) -> StatusWord | None:
        """The status word of a probe's answer, when it has one."""
        found = self.carrier.status(result)
        return StatusWord(self.name, found[0], found[1]) if found is not None else None

    def push_poll(self, poll: PollState) -> None:
        heapq.heappush(self.polls, (poll.due, next(self.seq), poll))

    def back(self, now: float) -> list[Described]:
        """The drive answers again after it was away: its polls are due now, its identity
        is read again (it may have been replaced by another drive), and what it left
        undescribed while away waits for its description again."""
        self.restart_polls(now)
        if self.describer is None:
            return []
        # Polls still held after their parameter settled wait for a type it refused.
        again = self.describer.recheck() + self.describer.reask(list(self.held))
        if not again:
            return []
        self._hold_again()
        targets = [t for t in self.spec.describe if t.pnu in again]
        why = "back after it was away"
        return [Forgotten(self.name, t, why) for t in targets]

    def restart_polls(self, now: float) -> None:
        """Every poll due now: after the drive or its line was away, none of them is late."""
        polls = [entry[2] for entry in self.polls]
        self.polls.clear()
        for poll in polls:
            poll.due = now
            self.push_poll(poll)


def expire(d: DrivePlan, queue: deque[Job] | deque[Job | ProbeJob], now: float) -> list[Event]:
    """End the jobs at the head of ``queue`` whose deadline passed before they were sent."""
    events: list[Event] = []
    while queue and queue[0].deadline <= now:
        job = queue.popleft()
        events.append(Finished(d.name, job, TimedOut("deadline passed before it was sent")))
    return events
