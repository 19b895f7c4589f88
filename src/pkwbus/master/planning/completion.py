"""A drive's transaction ends: what its end tells, and what the drive does next (pure).

A change's read-first gives way to the change itself (or ends the job); a
description element is folded into the drive's description; polls are due
again (polls carried in one record each with its own outcome, due again from
the request's first due, so that polls of one interval go out together); a
job is finished.
"""

from __future__ import annotations

from pkwbus.master.planning.describing import DescribeStep
from pkwbus.master.planning.drive import Active, DrivePlan
from pkwbus.master.planning.jobs import Job
from pkwbus.master.planning.outcomes import Outcome
from pkwbus.master.planning.plan import Event, Finished, PollBatch, PollState
from pkwbus.master.planning.transaction import BatchTransaction
from pkwbus.master.planning.write_gate import after_read

__all__ = ["complete", "drain", "withdraw"]


def complete(
    d: DrivePlan, active: Active, outcome: Outcome, now: float, *, retries: int
) -> list[Event]:
    """End ``d``'s transaction ``active`` with ``outcome``; the events it makes."""
    d.active = None
    d.lagging = False
    work = active.work
    if active.read_first and isinstance(work, Job):  # the read before a change
        after = after_read(d, active, work, outcome, retries=retries)
        if isinstance(after, Finished):
            return [after]
        d.active = after
        return []
    if isinstance(work, DescribeStep):
        return list(d.described(work, outcome, now))
    if isinstance(work, PollBatch):  # polls in one request: each with its own outcome
        tx, each = active.tx, [outcome] * len(work)
        if isinstance(tx, BatchTransaction) and tx.outcome is outcome:
            each = list(tx.outcomes)
        events: list[Event] = []
        for i, (poll, result) in enumerate(zip(work.polls, each, strict=True)):
            # The request's cost counted once; due again from the request's first due,
            # so that polls of one interval go out together (none later than due).
            tally = tx.tally if i == 0 else None
            events.append(Finished(d.name, poll.spec, result, tally))
            poll.due = max(active.order + poll.spec.every, now)
            if not poll.retired:
                d.push_poll(poll)
        return events
    if isinstance(work, PollState):
        work.due = max(work.due + work.spec.every, now)
        if not work.retired:
            d.push_poll(work)
        return [Finished(d.name, work.spec, outcome, active.tx.tally)]
    return [Finished(d.name, work, outcome, active.tx.tally)]


def drain(d: DrivePlan, outcome: Outcome) -> list[Event]:
    """End every job ``d`` has queued with ``outcome`` (the line stops or is lost, the drive
    goes in maintenance)."""
    return [
        Finished(d.name, queue.popleft(), outcome)
        for queue in (d.writes, d.reads, d.background)
        for _ in range(len(queue))
    ]


def withdraw(d: DrivePlan, outcome: Outcome, now: float, *, retries: int) -> list[Event]:
    """End all of ``d``'s work that is not on the wire with ``outcome`` (a drive put in
    maintenance): its queued jobs, and its transaction unless an exchange of it is out
    (that one ends at its result), a change that would follow its read included."""
    events = drain(d, outcome)
    while d.active is not None and not d.busy:
        events += complete(d, d.active, outcome, now, retries=retries)
    return events
