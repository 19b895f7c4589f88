"""What a reload changes in a running line's plan (pure): its drives (:class:`Roster`), and a
drive's polls as the new configuration gives them, without a gap (:func:`update_polls`).

A drive removed while an exchange of it is out leaves the roster at once; that
exchange's result still ends its work (a write the drive acknowledged is done),
and only a job's caller hears of it (:data:`Finished.gone`): nothing of it is
shown as the drive's (another drive of its name may have been added). A drive's
slot is never given again (it breaks ties in the planner's heaps).

A poll the new configuration keeps as it was (its parameter, index, request and
description) keeps its state: its due time, its place while it waits for its
parameter's description, its exchange in flight. A changed interval applies from
its next due time on. A new poll is due now, after its parameter's description
where that is still awaited; one of a parameter already described is decoded as
described at once. A poll no longer configured is not polled again: one in flight
ends at its result, and is not due again.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Sequence
from dataclasses import replace

from pkwbus.master.planning.describing import Settled, described_poll
from pkwbus.master.planning.drive import DrivePlan
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.plan import (
    Described,
    DescribeTarget,
    DriveSpec,
    Event,
    Finished,
    PollSpec,
    PollState,
    Redecoded,
    Send,
    polls_of,
)

__all__ = ["Roster", "only_callers", "update_polls"]


class Roster:
    """The drives of a line, in order and by name, and those that left with an exchange out."""

    def __init__(self, specs: Sequence[DriveSpec], policy: HealthPolicy) -> None:
        self.policy = policy
        self.drives = [DrivePlan(s, policy, i, len(specs)) for i, s in enumerate(specs)]
        self.by_name = {d.name: d for d in self.drives}
        self.leaving: dict[str, tuple[DrivePlan, str]] = {}
        self._slots = itertools.count(len(self.drives))

    def add(self, spec: DriveSpec) -> DrivePlan:
        slot = next(self._slots)
        d = DrivePlan(spec, self.policy, slot, slot + 1)
        self.drives.append(d)
        self.by_name[d.name] = d
        return d

    def remove(self, name: str, reason: str) -> DrivePlan:
        """Take ``name`` off the line (KeyError: not on it); kept as leaving while busy."""
        d = self.by_name.pop(name)
        self.drives.remove(d)
        if d.busy:
            self.leaving[name] = (d, reason)
        return d

    def of(self, send: Send) -> tuple[DrivePlan, str | None]:
        """The drive ``send`` was for, and the reason it left (None: on the line). On one
        line one exchange is out at a time: the first result of a name that left is its."""
        gone = self.leaving.pop(send.drive, None)
        return gone if gone is not None else (self.by_name[send.drive], None)

    def all(self) -> list[DrivePlan]:
        return [*self.drives, *(d for d, _ in self.leaving.values())]


def only_callers(events: list[Event]) -> list[Event]:
    """What a drive that left tells: its jobs' ends, to their callers alone."""
    return [
        replace(e, gone=True)
        for e in events
        if isinstance(e, Finished) and not isinstance(e.work, PollSpec)
    ]


_Key = tuple[str, int]


def _key(spec: PollSpec) -> _Key:
    return spec.parameter, spec.index


def update_polls(
    d: DrivePlan,
    polls: Sequence[PollSpec],
    describe: Sequence[DescribeTarget],
    now: float,
    events: list[Event],
) -> list[PollSpec]:
    """Give ``d`` the configuration's ``polls`` and what it has ``describe``d: each
    poll as it goes out now (as described); into ``events`` a :class:`Described` event for
    the new polls of each parameter already described (their decoding, for whoever shows
    them). A parameter no longer described stays known as it was."""
    _describe(d, describe)
    was = {_key(p): p for p in d.spec.polls}
    wanted = {_key(p): p for p in polls}
    kept: dict[_Key, PollSpec] = {}

    def keep(poll: PollState) -> bool:
        k = _key(poll.spec)
        new, old = wanted.get(k), was.get(k)
        if new is None or old is None or replace(old, every=new.every) != new:
            poll.retired = True  # not due again, whatever its exchange in flight brings
            return False
        poll.spec = replace(poll.spec, every=new.every)  # as described: its interval alone
        kept[k] = poll.spec
        return True

    d.polls[:] = [entry for entry in d.polls if keep(entry[2])]
    heapq.heapify(d.polls)
    for pnu, held in list(d.held.items()):
        held[:] = [poll for poll in held if keep(poll)]
        if not held:
            del d.held[pnu]
    work = d.active.work if d.active is not None else None
    for poll in polls_of(work):
        keep(poll)
    d.spec = replace(d.spec, polls=tuple(polls))
    described: dict[int, list[PollSpec]] = {}
    specs = []
    for k, spec in wanted.items():
        if k in kept:
            specs.append(kept[k])
            continue
        added, told = _add(d, spec, now)
        specs.append(added)
        if told:
            described.setdefault(spec.request.pnu, []).append(added)
    events += _described(d, described)
    return specs


def _describe(d: DrivePlan, targets: Sequence[DescribeTarget]) -> None:
    new = {t.pnu for t in targets}
    kept = tuple(t for t in d.spec.describe if t.pnu not in new)
    if d.describer is not None:
        for target in targets:
            d.describer.want(target.pnu, target.elements)
    d.spec = replace(d.spec, describe=(*targets, *kept))


def _add(d: DrivePlan, spec: PollSpec, now: float) -> tuple[PollSpec, bool]:
    """A new poll, due now: its spec as it goes out, and whether it is decoded as its
    parameter's description already says."""
    poll = PollState(spec, now)
    pnu = spec.request.pnu
    describer = d.describer
    if describer is None or pnu not in describer.described:
        if describer is not None and describer.waiting(pnu):
            d.held.setdefault(pnu, []).append(poll)  # due once it is described
        else:
            d.push_poll(poll)
        return spec, False
    found = describer.described[pnu]
    if (found is None or found.vtype is None) and spec.described_only:
        d.held.setdefault(pnu, []).append(poll)  # no type: it waits, as at the start
        return spec, False
    poll.spec = described_poll(spec, Settled(pnu, found, first=False), describer.dialect)
    d.push_poll(poll)
    return poll.spec, True


def _described(d: DrivePlan, described: dict[int, list[PollSpec]]) -> list[Described]:
    if not described or d.describer is None:
        return []
    targets = {t.pnu: t for t in d.spec.describe}
    found = d.describer.described
    return [
        Redecoded(d.name, targets[pnu], found[pnu], tuple(specs), d.describer.identity)
        for pnu, specs in described.items() if pnu in targets
    ]  # fmt: skip
