"""What a line sends next, as a state machine without I/O: time and results in, actions out.

The policy, in order:

- a drive's transaction in flight goes on before anything new of that drive
  (its parameter channel holds one request);
- across drives: writes, then on-demand reads, then due polls (and probes of a down
  drive), then background jobs; among equals the earliest deadline or due time, then
  the drive served longest ago (fairness);
- a drive whose last answer was "not yet", or missing, yields to another
  drive's exchange of the same priority before its repeat (lag interleaving);
- a drive without a valid answer for ``down_after`` exchanges is down: its
  poll in flight ends, and it is probed with one short telegram at capped
  exponential back-off until it answers; then all its polls are due at once
  (none counts as an overrun);
- a poll that starts more than one interval after it was due is an overrun; nothing is
  sent past its deadline; a job still queued at its deadline ends;
- a drive in maintenance gets nothing (no poll, job or probe) and is neither up nor down;
  out of it, it is a drive that came back (identified again, its polls due).

Drives wait for their turn on an :class:`~pkwbus.master.planning.agenda.Agenda` (two
heaps), so one exchange costs O(log n) in the number of drives.

A line asks :meth:`Planner.next_action`; a PROFIBUS DP cycle asks
:meth:`Planner.next_for` for each slave's turn, under the same priorities.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

from pkwbus.master.planning.agenda import Agenda
from pkwbus.master.planning.answers import ErrorKind, ExchangeResult, Failure
from pkwbus.master.planning.carrier import Transaction
from pkwbus.master.planning.completion import complete, drain, withdraw
from pkwbus.master.planning.drive import Active, DrivePlan, expire
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.jobs import Cancelled, Job, Priority, ProbeJob
from pkwbus.master.planning.outcomes import LineFailed, Outcome, TimedOut
from pkwbus.master.planning.plan import (
    Action,
    DriveSpec,
    Event,
    Finished,
    HealthChanged,
    Idle,
    PkwLengthTold,
    PollBatch,
    PollSpec,
    PollState,
    Send,
    StatusWord,
)
from pkwbus.master.planning.reload import Roster, only_callers, update_polls
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.master.planning.write_gate import gate_write

__all__ = ["IDLE_AT_MOST", "IN_MAINTENANCE", "NOT_HERE", "PORT_CLOSED", "Planner"]

PORT_CLOSED = "the line's port is not open"
IN_MAINTENANCE = "the drive is in maintenance"
NOT_HERE = "the drive is not on its line now: a reload changed it"
IDLE_AT_MOST = 3600.0


class Planner:
    """Chooses every exchange of one line; reports what came of them as events."""

    def __init__(
        self,
        drives: Sequence[DriveSpec],
        *,
        poll_deadline: float,
        retries: int = 2,
        policy: HealthPolicy | None = None,
    ) -> None:
        policy = policy or HealthPolicy()
        self.retries = retries
        self.poll_deadline = poll_deadline  # a poll's transaction, retries included
        self._roster = Roster(drives, policy)  # the drives; a reload adds and removes them
        self.drives, self._by_name = self._roster.drives, self._roster.by_name
        self.events: list[Event] = []
        self.up = False  # the line's port is open
        self.stopping = False
        self._agenda: Agenda[DrivePlan] = Agenda(len(self.drives))
        self._served = itertools.count()
        self._job_seq = itertools.count()
        self._lagging: list[DrivePlan] = []

    def drive(self, name: str) -> DrivePlan:
        """The plan of drive ``name`` (KeyError for a drive not on this line)."""
        return self._by_name[name]

    def add_drive(self, spec: DriveSpec, now: float) -> None:
        """A drive added to the line (a reload): planned as at the start, its polls due now."""
        d = self._roster.add(spec)
        self._agenda.grow(len(self.drives))
        d.restart_polls(now)
        self._index(d, now)

    def remove_drive(self, name: str, reason: str, now: float) -> None:
        """A drive gone: its work ends with ``reason`` (one on the wire at its result)."""
        d = self._roster.remove(name, reason)
        d.maintenance = True  # no claim, ever again
        d.went_down()  # another drive of its kind describes what it was describing
        self.events += only_callers(withdraw(d, Cancelled(reason), now, retries=self.retries))
        d.version += 1

    def update_polls(self, spec: DriveSpec, now: float) -> list[PollSpec]:
        """The drive's polls and described parameters now (:mod:`.reload`), as they go out."""
        d = self._by_name[spec.name]
        specs = update_polls(d, spec.polls, spec.describe, now, self.events)
        self._index(d, now)
        return specs

    def take_events(self) -> list[Event]:
        events, self.events = self.events, []
        return events

    # ------------------------------------------------------------- inputs

    def submit(self, job: Job | ProbeJob, now: float) -> None:
        """Queue a write, an on-demand read or a probe (one for a drive not here ends now)."""
        if (d := self._by_name.get(job.drive)) is None:  # a reload took it away meanwhile
            self.events.append(Finished(job.drive, job, Cancelled(NOT_HERE), gone=True))
            return
        if self.stopping:
            self.events.append(Finished(d.name, job, Cancelled("the service is stopping")))
            return
        if not self.up:
            self.events.append(Finished(d.name, job, LineFailed(PORT_CLOSED)))
            return
        if d.maintenance:
            self.events.append(Finished(d.name, job, Cancelled(IN_MAINTENANCE)))
            return
        if isinstance(job, Job) and job.priority is not Priority.READ:
            (d.writes if job.priority is Priority.WRITE else d.background).append(job)
        else:
            d.reads.append(job)
        self._agenda.expiry(d, job.deadline)
        self._index(d, now)

    def line_up(self, now: float) -> None:
        """The port is open: every poll is due now (none is late: the line was away)."""
        self.up = True
        for d in self.drives:
            d.restart_polls(now)
            self._index(d, now)

    def line_down(self, now: float) -> None:
        """The port is not open: no job waits for it, nothing in flight is sent later."""
        self.up = False
        self._lagging.clear()
        self._roster.leaving.clear()  # their exchanges ended with the port
        for d in self.drives:
            d.busy = d.lagging = False
            if d.describer is not None:
                d.describer.release()  # another line's drive of its kind describes instead
            if d.active is not None:
                self._complete(d, d.active, LineFailed(PORT_CLOSED), now)
            self.events += drain(d, LineFailed(PORT_CLOSED))
            d.version += 1

    def maintenance(self, drive: str, on: bool, now: float) -> None:
        """Put ``drive`` in maintenance (nothing goes out to it: its queued jobs end, its
        transaction ends once no exchange of it is out) or take it out (a drive that came
        back: identified again, its polls due now, up at its first answer). KeyError for a
        drive not on this line."""
        d = self._by_name[drive]
        if d.maintenance == on:
            return
        d.maintenance = on
        if on:
            self.events += withdraw(d, Cancelled(IN_MAINTENANCE), now, retries=self.retries)
            self._tell(d.went_down())  # it may come back as another drive
        else:
            d.health.reset()
            d.shown_up = False  # up again at its first answer
            if d.carrier.tells_health:  # down until its wire tells it is back (a DP slave)
                self._show(d, False, "out of maintenance, not in data exchange yet")
            self.events.extend(d.back(now))
        self._index(d, now)

    def port_failed(self) -> None:
        """The port failed: nobody can tell whether the drives answer (those in maintenance
        are neither up nor down)."""
        for d in self.drives:
            if not d.maintenance:
                self._show(d, False, "")

    def stop(self, reason: str) -> None:
        """Take no new jobs; cancel the queued ones and the jobs in flight."""
        self.stopping = True
        for d in self._roster.all():
            active, d.active = d.active, None
            if active is not None and isinstance(active.work, Job | ProbeJob):
                tally = None if active.read_first else active.tx.tally  # a write not yet sent
                self.events.append(Finished(d.name, active.work, Cancelled(reason), tally))
            self.events += drain(d, Cancelled(reason))
            d.version += 1

    # ------------------------------------------------------------ choices

    def next_action(self, now: float) -> Action:
        """The line's next exchange, or how long it may stay idle."""
        if not self.up or self.stopping:
            return Idle(now + IDLE_AT_MOST)
        agenda = self._agenda
        while True:
            self._fire(now)
            d = agenda.first()
            if d is None:
                at = agenda.next_time()
                return Idle(now + IDLE_AT_MOST if at is None else min(at, now + IDLE_AT_MOST))
            send = self._start(d, now)
            if send is not None:
                return send

    def next_for(self, drive: str, now: float) -> Send | None:
        """The next exchange of ``drive`` alone (one slot of a cyclic line), or None."""
        d = self._by_name[drive]
        if not self.up or self.stopping or d.busy:
            return None
        self._fire(now)
        while d.claim(now, self.events)[0] is not None:
            send = self._start(d, now)
            if send is not None:
                return send
        return None

    def active(self, drive: str) -> Transaction | None:
        """The transaction ``drive``'s slot carries (after :meth:`next_for` gave its Send)."""
        return a.tx if (a := self._by_name[drive].active) is not None else None

    def sending(self, drive: str) -> Send | None:
        """The exchange carrying ``drive``'s transaction (a cyclic slot's, over many cycles)."""
        return a.send if (a := self._by_name[drive].active) is not None else None

    def expire_queued(self, drive: str, now: float) -> None:
        """End the jobs of ``drive`` past their deadline while nothing can go out to it,
        queued or in flight between its tries."""
        d = self._by_name[drive]
        for queue in (d.writes, d.reads, d.background):
            self.events += expire(d, queue, now)
        active = d.active
        if active is not None and not d.busy and now >= active.tx.deadline:
            self._complete(d, active, TimedOut("deadline passed"), now)
            self._index(d, now)

    def told_health(self, drive: str, up: bool, reason: str, now: float) -> None:
        """The wire tells ``drive``'s health (a DP slave in data exchange, or out of it); back
        up, its polls are due now, none counted as an overrun."""
        d = self._by_name[drive]
        if d.maintenance:  # neither up nor down: it is sent nothing
            return
        self._show(d, up, reason)
        if up:
            self.events.extend(d.back(now))
            self._index(d, now)

    def exchanged(self, send: Send, result: ExchangeResult, now: float) -> None:
        """The result of ``send``'s exchange (of a drive removed with it out first: one of
        its name may be back already)."""
        d, why = self._roster.of(send)
        mark = len(self.events)
        d.busy = False
        d.served = next(self._served)
        if self._lagging:  # another drive had its turn: the lagging ones may go again
            for other in self._lagging:
                if other is not d and other.lagging:
                    other.lagging = False
                    self._index(other, now)
            self._lagging.clear()
        if d.maintenance:  # out before the drive went in maintenance: nothing follows it
            if (active := d.active) is not None and active.send is send:
                # Its answer still counts (an acknowledged write is done; the telegram
                # went out either way), but nothing is repeated or sent after it.
                outcome = active.tx.feed(result, now)
                self._complete(d, active, outcome or Cancelled(why or IN_MAINTENANCE), now)
            self.events += withdraw(d, Cancelled(why or IN_MAINTENANCE), now, retries=self.retries)
            if why is not None:  # it left the line: its callers alone hear of it
                self.events[mark:] = only_callers(self.events[mark:])
            self._index(d, now)
            return
        self._health(d, result, now)
        if send.probe and not isinstance(result, Failure):  # a down drive's, or a probe job's
            if (status := d.status_of(result)) is not None:
                self.events.append(status)
            self._tell(d.probed(send, result))
        if (active := d.active) is not None and active.send is send:
            tx = active.tx
            outcome = tx.feed(result, now)
            if not isinstance(result, Failure) and isinstance(tx, PkwTransaction):
                self._tell(d.heard(tx))
            tally = tx.tally
            if not send.probe and not isinstance(result, Failure) and tally.status_word is not None:
                self.events.append(StatusWord(d.name, tally.status_word, tally.main_actual))
            if outcome is None:
                # A "not yet" or a failed try: the repeat yields to another drive's
                # exchange first, so a lagging or dying drive cannot hold the line.
                d.lagging = tx.waiting or isinstance(result, Failure)
                if d.lagging:
                    self._lagging.append(d)
            else:
                self._complete(d, active, outcome, now)
        self._index(d, now)

    # ---------------------------------------------------------- internals

    def _index(self, d: DrivePlan, now: float) -> None:
        """Put the drive in the heap it belongs to now (its older entries go stale)."""
        d.version += 1
        key, at = d.claim(now, self.events)
        if d.busy or not self.up or self.stopping:
            return
        if key is not None:
            self._agenda.ready(d, key)
        if at is not None:  # also a background claim's next poll: it takes over when due
            self._agenda.later(d, at)

    def _fire(self, now: float) -> None:
        for d in self._agenda.due(now):
            self._index(d, now)

    def _start(self, d: DrivePlan, now: float) -> Send | None:
        """Begin the drive's exchange; None when its transaction ended instead."""
        d.version += 1  # out of the heaps until its result comes back
        a = d.active
        if a is not None:
            if now >= a.tx.deadline:  # never resend a request past its deadline
                self._complete(d, a, TimedOut("deadline passed"), now)
                self._index(d, now)
                return None
            d.busy = True
            return a.send
        # Taken off the ready heap at its version: only a queued job's deadline can have
        # ended its claim since (a poll or probe due stays due).
        if (d.writes or d.reads or d.background) and d.claim(now, self.events)[0] is None:
            self._index(d, now)  # its queued jobs ended at their deadline
            return None
        d.busy = True
        due = d.first_due()
        idle = d.health.up and (due is None or due > now)  # no probe or poll before it
        queue = d.writes or d.reads or (d.background if idle else None)
        if queue:
            job = queue.popleft()
            order = float(next(self._job_seq))
            if isinstance(job, ProbeJob):
                first = d.probe_job(job, order, retries=self.retries)
            else:
                first = gate_write(d, job, order, retries=self.retries)
            if isinstance(first, Finished):  # not to be sent: the drive goes on
                self.events.append(first)
                d.busy = False
                self._index(d, now)
                return None
            d.active = first
            return first.send
        if not d.health.up:
            probe = d.next_probe()
            if probe is None:  # its carrier never probes: its health is told
                d.busy = False
            return probe
        active, events = d.start_poll(now, now + self.poll_deadline, self.retries)
        self.events.extend(events)
        if active is None:  # its descriptions are another drive's to ask
            d.busy = False
            self._index(d, now)
            return None
        d.active = active
        return active.send

    def _tell(self, event: PkwLengthTold | None) -> None:
        if event is not None:
            self.events.append(event)

    def _complete(self, d: DrivePlan, active: Active, outcome: Outcome, now: float) -> None:
        self.events.extend(complete(d, active, outcome, now, retries=self.retries))

    def _health(self, d: DrivePlan, result: ExchangeResult, now: float) -> None:
        if not isinstance(result, Failure):
            if d.health.answered():
                self._show(d, True, "answers again")
                self.events.extend(d.back(now))  # not overruns: the drive was away
            elif not d.shown_up:
                self._show(d, True, "")  # back after its line was down
            return
        if result.kind is ErrorKind.PORT or d.describing:  # a drive may ignore AK 4 alone
            return
        if d.health.failed(now):
            self._show(d, False, result.kind.value)
            self._tell(d.went_down())  # its PKW length and identity are asked again
            active = d.active
            if active is not None and isinstance(active.work, PollState | PollBatch):
                self._complete(d, active, TimedOut("drive is down"), now)

    def _show(self, d: DrivePlan, up: bool, reason: str) -> None:
        d.shown_up = up
        self.events.append(HealthChanged(d.name, up, reason))
