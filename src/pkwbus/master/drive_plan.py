"""A drive as the planner sees it: its queues, its transaction in flight, its polls, its health."""

from __future__ import annotations

import heapq
import itertools
from collections import deque
from dataclasses import dataclass, replace

from pkwbus.master.health import DriveHealth, HealthPolicy
from pkwbus.master.jobs import Job, Priority
from pkwbus.master.plan import DriveSpec, PkwLengthTold, PollSpec, Send
from pkwbus.master.transaction import PkwTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw_length import PkwLength
from pkwbus.protocol.telegram import Protocol

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
    # The read of a change's parameter before the change (master.write_gate).
    read_first: bool = False


class DrivePlan:
    __slots__ = (
        "active", "busy", "health", "lagging", "last_answer", "name", "pkw", "polls", "probe",
        "probes", "reads", "seq", "served", "shown_up", "slot", "spec", "target", "version",
        "writes",
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
        # USS: the drive's PKW length, configured or told by its answers.
        target = spec.target
        uss = target.protocol is Protocol.USS and target.has_pkw
        self.pkw = PkwLength(target.pkw_setting) if uss else None
        self.last_answer: bytes | None = None  # PKW bytes of its latest answer (not AK 0)
        self.probes = 0

    def next_probe(self) -> Send:
        """The probe of a down drive. While a learned PKW length is not known, every other
        probe has 3 PKW words: a fixed-3 drive answers no 4-word request (SINAMICS S110
        Function Manual, 9.5: with a fixed length "the slave will not respond" to another)."""
        self.probes += 1
        length = self.pkw
        if length is None or length.known or not self.target.learn or self.probes % 2:
            return self.probe
        short = self.target.with_pkw_words(3)
        return Send(self.name, short, short.probe(), True)

    def probed(self, send: Send, data: bytes) -> PkwLengthTold | None:
        """A probe was answered (``data``: its telegram's data); the event when a 3-word one
        told the drive's length: 3 words back is a fixed-3 drive (its 4-word requests went
        unanswered), any other length a variable one."""
        length = self.pkw
        if length is None or length.known or send.target.shape.pkw_words != 3:
            return None
        answer_words = len(data) // 2 - send.target.shape.pzd_words
        if answer_words == 3:
            length.words, length.known = 3, True
        else:
            length.observe(3, answer_words, pkw.NoResponse(0, 0, 0))
        return self.retarget()

    def heard(self, tx: PkwTransaction) -> PkwLengthTold | None:
        """Take what the answer ``tx`` just decoded tells; the event when the drive's PKW
        length, as known, changed (requests then go out with the new one)."""
        answer, response = tx.answer_pkw, tx.response
        if answer is None or response is None:
            return None
        if not isinstance(response, pkw.NoResponse):
            self.last_answer = answer
        length = self.pkw
        if length is None:
            return None
        sent = self.target.pkw_words_of(tx.telegram)
        if not length.observe(sent, len(answer) // 2, response):
            return None
        return self.retarget()

    def forget_pkw(self) -> PkwLengthTold | None:
        """The drive went down: a learned PKW length is learned again when it answers."""
        length = self.pkw
        if length is None or not self.target.learn or not length.known:
            return None
        length.forget()
        return self.retarget()

    def retarget(self) -> PkwLengthTold | None:
        """Requests go out with the PKW length as known now (a learned one); the event
        that tells what is known of it now."""
        length = self.pkw
        if length is None:
            return None
        if self.target.learn and length.words != self.target.shape.pkw_words:
            target = self.target = self.target.with_pkw_words(length.words)
            self.probe = Send(self.name, target, target.probe(), True)
            for _, _, poll in self.polls:
                poll.send = Send(self.name, target, target.telegram(poll.spec.request))
        return PkwLengthTold(self.name, replace(length))

    def push_poll(self, poll: PollState) -> None:
        if poll.send.target is not self.target:  # built before the PKW length was learned
            poll.send = Send(self.name, self.target, self.target.telegram(poll.spec.request))
        heapq.heappush(self.polls, (poll.due, next(self.seq), poll))

    def restart_polls(self, now: float) -> None:
        """Every poll due now: after the drive or its line was away, none of them is late."""
        polls = [entry[2] for entry in self.polls]
        self.polls.clear()
        for poll in polls:
            poll.due = now
            self.push_poll(poll)
