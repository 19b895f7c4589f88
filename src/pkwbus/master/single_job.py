"""One job on an open FC or USS line by the planner, for a caller that runs no service.

The command line's ``read``, ``write``, ``describe`` and ``scan`` use it: the
same planner and PKW transaction as the service (the read before a change,
the PKW length learned), one drive, no polls, each exchange awaited.
"""

from __future__ import annotations

import asyncio

from pkwbus.master.jobs import Job, JobKind, Priority
from pkwbus.master.line import Line
from pkwbus.master.outcomes import Outcome
from pkwbus.master.plan import DriveSpec, Finished, Send
from pkwbus.master.planner import Planner
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw

__all__ = ["perform", "run_job"]


async def run_job(
    line: Line,
    target: DriveTarget,
    request: pkw.PkwRequest,
    *,
    retries: int = 2,
    deadline: float,
) -> Outcome:
    """One job on an open line, by the service's planner (no other drive, no polls)."""
    finished = await perform(line, target, request, retries=retries, deadline=deadline)
    return finished.outcome


async def perform(
    line: Line,
    target: DriveTarget,
    request: pkw.PkwRequest,
    *,
    retries: int = 2,
    deadline: float,
) -> Finished:
    """:func:`run_job`, with what its exchanges cost (``tally``)."""
    loop = asyncio.get_running_loop()
    planner = Planner([DriveSpec("drive", target)], poll_deadline=deadline, retries=retries)
    planner.line_up(loop.time())
    kind = JobKind.WRITE if request.is_write else JobKind.READ
    priority = Priority.WRITE if request.is_write else Priority.READ
    planner.submit(Job("drive", request, kind, priority, deadline), loop.time())
    while True:
        for event in planner.take_events():
            if isinstance(event, Finished) and isinstance(event.work, Job):
                return event
        action = planner.next_action(loop.time())
        if isinstance(action, Send):
            result = await line.exchange(action.target, action.telegram)
            planner.exchanged(action, result, loop.time())
        elif not planner.events:  # nothing to do before the job's deadline: it has ended
            await asyncio.sleep(max(0.0, min(action.until, deadline) - loop.time()))
