"""A drive as the planner sees it: its queues, its transaction in flight, its polls, its health."""

from __future__ import annotations

import heapq
import itertools
from collections import deque
from dataclasses import dataclass

from pkwbus.master.health import DriveHealth, HealthPolicy
from pkwbus.master.jobs import Job, Priority
from pkwbus.master.plan import DriveSpec, PollSpec, Send
from pkwbus.master.transaction import PkwTransaction

__all__ = ["Active", "DrivePlan", "PollState"]


class PollState:
    """A poll and when it is due; its request telegram is built once."""

    __slots__ = ("due", "send", "spec")

    def __init__(self, spec: PollSpec, due: float, send: Send) -> None:
        self.spec = spec
        self.due = due
        self.send = send


@dataclass(eq=False, slots=True)
class Active:
    """A drive's transaction in flight: a queued job's, or a poll's."""

    tx: PkwTransaction
    priority: Priority
    order: float
    work: Job | PollState
    send: Send


class DrivePlan:
    __slots__ = (
        "active", "busy", "health", "lagging", "name", "polls", "probe", "reads", "seq",
        "served", "shown_up", "slot", "spec", "target", "version", "writes",
    )  # fmt: skip

    def __init__(self, spec: DriveSpec, policy: HealthPolicy, slot: int, count: int) -> None:
        self.spec = spec
        self.name = spec.name
        self.target = spec.target
        self.slot = slot
        self.served = slot - count  # never served yet: in configuration order
        self.version = 0
        self.busy = False  # its exchange is out: not in the ready heap
        self.health = DriveHealth(policy)
        self.shown_up = True
        self.writes: deque[Job] = deque()
        self.reads: deque[Job] = deque()
        self.active: Active | None = None
        self.lagging = False
        self.probe = Send(spec.name, spec.target, spec.target.probe(), True)
        self.seq = itertools.count()
        self.polls: list[tuple[float, int, PollState]] = []
        for p in spec.polls:
            send = Send(spec.name, spec.target, spec.target.telegram(p.request))
            self.push_poll(PollState(p, 0.0, send))

    def push_poll(self, poll: PollState) -> None:
        heapq.heappush(self.polls, (poll.due, next(self.seq), poll))

    def restart_polls(self, now: float) -> None:
        """Every poll due now: after the drive or its line was away, none of them is late."""
        polls = [entry[2] for entry in self.polls]
        self.polls.clear()
        for poll in polls:
            poll.due = now
            self.push_poll(poll)
