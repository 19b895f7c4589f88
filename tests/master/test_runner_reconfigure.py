"""A reload on a running line, end to end over simulated drives: the snapshot follows it.

A drive removed leaves the snapshot at once and for good (nothing more goes out to
it; its queued jobs' callers are answered); a drive added shows its values; a poll
removed takes its reading along while the line's other readings keep being
refreshed. The planner's side (due times, what goes out) is tested on a fake clock
in planning/test_reconfigure.py.
"""

from __future__ import annotations

import asyncio
import dataclasses
import itertools
from collections.abc import Iterable

from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.planning.jobs import Cancelled, Job, JobKind, JobResult, Priority
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import PollSpec, PollState
from pkwbus.master.runner import LineRunner
from pkwbus.master.snapshot import DriveState, ReadingKey, Snapshot
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.serial.telegram import Telegram
from pkwbus.sim import SimTiming, Simulator
from tests.master.conftest import make_sim, serve, until
from tests.master.test_runner import Recorder, drive_specs, runner

REASON = "gone from the configuration"


def counter() -> itertools.count[int]:
    return itertools.count(1000)


def shown(snapshot: Snapshot, drive: str) -> list[object]:
    """Everything the snapshot shows of ``drive``."""
    found: list[object] = []
    for entries in (snapshot.readings, snapshot.latest, snapshot.stated):
        found += [k for k in entries if k[0] == drive]
    for by_drive in (snapshot.drives, snapshot.slaves, snapshot.maintenance):
        found += [k for k in by_drive if k == drive]
    return found


def to_address(sim: Simulator, sent: Iterable[bytes], protocol: str, address: int) -> int:
    """How many of the telegrams ``sent`` went to drive ``address``."""
    adr = SerialCarrier(DriveTarget.create(protocol, address)).address
    return sum(
        1
        for data in sent
        for t in sim.deframer().feed(data)
        if isinstance(t, Telegram) and t.adr == adr
    )


async def refreshed(s: LineRunner, keys: Iterable[ReadingKey]) -> None:
    """Until every reading of ``keys`` is newer than it is now (the wall clock counts)."""
    readings = s.snapshot.readings
    stamp = {k: readings[k].timestamp for k in keys}
    await until(lambda: all(k in readings and readings[k].timestamp > t for k, t in stamp.items()))


def jobs_done(events: Recorder, drive: str) -> int:
    """How many jobs and polls of ``drive`` the line's observer was told of."""
    return sum(1 for d, _, _ in events.done if d == drive)


async def test_a_removed_drive_leaves_the_snapshot_for_good() -> None:
    sim = make_sim("fc", [1, 2])
    stamps = counter()
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1, 2], [1613, 1614], 0.02)
        s, events, trace = runner(port, "fc", specs, wall_clock=lambda: float(next(stamps)))
        task = asyncio.create_task(s.run())
        try:
            await until(
                lambda: (
                    len(s.snapshot.readings) == 4
                    and s.snapshot.drives["d2"].status_word is not None
                )
            )
            assert shown(s.snapshot, "d2")
            loop = asyncio.get_running_loop()
            future: asyncio.Future[JobResult] = loop.create_future()
            old = sim.drives[2].value(341)
            write = pkw.write(specs[1].carrier.dialect, 341, old + 1, pkw.Width.DWORD)
            s.submit(
                Job("d2", write, JobKind.WRITE, Priority.WRITE, loop.time() + 5, future=future)
            )
            s.remove_drive("d2", REASON)  # the write is still queued
            sent = len(trace.tx)
            done = jobs_done(events, "d2")
            assert shown(s.snapshot, "d2") == []
            result = await asyncio.wait_for(future, 2.0)
            assert result.outcome == Cancelled(REASON)
            for _ in range(5):  # the other drive's readings are refreshed; d2's stay away
                await refreshed(s, [("d1", "1613", 0), ("d1", "1614", 0)])
                assert shown(s.snapshot, "d2") == []
            # An exchange of it that was on the wire, at most; its write never went out.
            assert to_address(sim, trace.tx[sent:], "fc", 2) <= 1
            assert sim.drives[2].value(341) == old
            assert jobs_done(events, "d2") == done, "nothing of it told after it went"
        finally:
            s.stop()
            await asyncio.wait_for(task, 2.0)
    assert shown(s.snapshot, "d2") == []
    assert set(s.snapshot.readings) == {("d1", "1613", 0), ("d1", "1614", 0)}


async def test_a_removed_drive_in_maintenance_leaves_the_snapshot() -> None:
    sim = make_sim("fc", [1, 2])
    async with serve(sim, "tcp") as port:
        s, _, _ = runner(port, "fc", drive_specs("fc", [1, 2], [1613], 0.02))
        task = asyncio.create_task(s.run())
        try:
            await until(lambda: len(s.snapshot.readings) == 2)
            s.maintenance("d2", True, "its motor is changed")
            assert "d2" in s.snapshot.maintenance
            s.remove_drive("d2", REASON)
            assert shown(s.snapshot, "d2") == []
            await refreshed(s, [("d1", "1613", 0)])
            assert shown(s.snapshot, "d2") == []
        finally:
            s.stop()
            await asyncio.wait_for(task, 2.0)
    assert shown(s.snapshot, "d2") == []


async def test_a_lagging_job_of_a_removed_drive_is_answered() -> None:
    """The drive lags: its read is on the wire or between its tries when the drive goes.
    Its caller gets a result all the same, and nothing more goes out to the drive."""
    timing = SimTiming(response_delay=0.0, lag_telegrams=1000, lag_mode="none")
    sim = make_sim("uss", [1, 2], timing=timing)
    async with serve(sim, "tcp") as port:
        specs = drive_specs("uss", [1, 2], [1120], 0.02)
        s, _, trace = runner(port, "uss", specs, timeout=0.05)
        task = asyncio.create_task(s.run())
        try:
            await until(lambda: len(trace.tx) >= 2)  # the port is open: d1's polls go out
            loop = asyncio.get_running_loop()
            future: asyncio.Future[JobResult] = loop.create_future()
            read = pkw.read(specs[1].carrier.dialect, 1121)
            s.submit(Job("d2", read, JobKind.READ, Priority.READ, loop.time() + 30, future=future))
            await until(lambda: to_address(sim, trace.tx, "uss", 2) >= 3)  # repeated: it lags
            assert not future.done(), future.result()
            s.remove_drive("d2", REASON)
            sent = len(trace.tx)
            result = await asyncio.wait_for(future, 2.0)
            assert isinstance(result.outcome, Cancelled)
            await until(lambda: len(trace.tx) >= sent + 20)  # d1's polls go on
            assert to_address(sim, trace.tx[sent:], "uss", 2) <= 1
            assert shown(s.snapshot, "d2") == []
        finally:
            s.stop()
            await asyncio.wait_for(task, 2.0)


SLOW = SimTiming(response_delay=0.05)  # each exchange is on the wire long enough to be seen


def on_the_wire(s: LineRunner, drive: str, work: type | object) -> bool:
    """Whether ``drive``'s exchange is out (its result to come) for ``work``: a job, or a
    poll of that parameter label."""
    d = s.planner.drive(drive)
    active = d.active
    if not d.busy or active is None:
        return False
    if isinstance(work, str):
        return isinstance(active.work, PollState) and active.work.spec.parameter == work
    return active.work is work


async def test_a_drive_removed_while_its_poll_is_on_the_wire_does_not_come_back() -> None:
    sim = make_sim("fc", [1, 2], timing=SLOW)
    stamps = counter()
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1, 2], [1613], 0.0)
        s, events, trace = runner(
            port, "fc", specs, timeout=1.0, wall_clock=lambda: float(next(stamps))
        )
        task = asyncio.create_task(s.run())
        try:
            await until(lambda: len(s.snapshot.readings) == 2)
            await until(lambda: on_the_wire(s, "d2", "1613"))
            s.remove_drive("d2", REASON)
            sent, done = len(trace.tx), jobs_done(events, "d2")
            assert shown(s.snapshot, "d2") == []
            for _ in range(3):  # d1's exchanges come after d2's answer, recorded in order
                await refreshed(s, [("d1", "1613", 0)])
                assert shown(s.snapshot, "d2") == []
            assert to_address(sim, trace.tx[sent:], "fc", 2) <= 1
            assert jobs_done(events, "d2") == done
        finally:
            s.stop()
            await asyncio.wait_for(task, 5.0)
    assert shown(s.snapshot, "d2") == []


async def test_a_job_of_a_drive_removed_while_it_is_on_the_wire_is_answered() -> None:
    sim = make_sim("fc", [1, 2], timing=SLOW)
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1, 2], [1613], 0.0)
        s, _, trace = runner(port, "fc", specs, timeout=1.0)
        task = asyncio.create_task(s.run())
        try:
            await until(lambda: len(s.snapshot.readings) == 2)
            loop = asyncio.get_running_loop()
            future: asyncio.Future[JobResult] = loop.create_future()
            read = Job(
                "d2", pkw.read(specs[1].carrier.dialect, 1530), JobKind.READ, Priority.READ,
                loop.time() + 30, future=future,
            )  # fmt: skip
            s.submit(read)
            await until(lambda: on_the_wire(s, "d2", read))
            s.remove_drive("d2", REASON)
            sent = len(trace.tx)
            assert not future.done()
            result = await asyncio.wait_for(future, 5.0)
            assert isinstance(result.outcome, Answered)  # its answer came: it counts
            await refreshed(s, [("d1", "1613", 0)])
            assert to_address(sim, trace.tx[sent:], "fc", 2) <= 1
            assert shown(s.snapshot, "d2") == []
        finally:
            s.stop()
            await asyncio.wait_for(task, 5.0)


async def test_an_added_drive_shows_its_values() -> None:
    sim = make_sim("fc", [1, 3])
    stamps = counter()
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1], [1613, 1614], 0.02)
        s, events, _ = runner(port, "fc", specs, wall_clock=lambda: float(next(stamps)))
        task = asyncio.create_task(s.run())
        try:
            await until(lambda: len(s.snapshot.readings) == 2)
            s.add_drive(drive_specs("fc", [3], [341, 1530], 0.02)[0])
            assert s.snapshot.drives["d3"] == DriveState()  # up until it fails, no value yet
            await until(
                lambda: (
                    {("d3", "341", 0), ("d3", "1530", 0)} <= s.snapshot.readings.keys()
                    and s.snapshot.drives["d3"].status_word is not None
                )
            )
            assert s.snapshot.readings[("d3", "341", 0)].value == sim.drives[3].value(341)
            assert s.snapshot.drives["d3"].status_word == sim.drives[3].status_word
            assert s.snapshot.drives["d3"].up
            keys = [("d1", "1613", 0), ("d1", "1614", 0), ("d3", "341", 0), ("d3", "1530", 0)]
            for _ in range(3):
                await refreshed(s, keys)
            assert events.polls_ok("d3") >= 6
        finally:
            s.stop()
            await asyncio.wait_for(task, 2.0)


async def test_a_removed_poll_leaves_the_readings_while_the_others_go_on() -> None:
    sim = make_sim("fc", [1, 2])
    stamps = counter()
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1, 2], [1613, 1614], 0.02)
        s, _, trace = runner(port, "fc", specs, wall_clock=lambda: float(next(stamps)))
        task = asyncio.create_task(s.run())
        gone = ("d1", "1613", 0)
        try:
            await until(lambda: len(s.snapshot.readings) == 4)
            _, kept = specs[0].polls
            target = DriveTarget.create("fc", 1)
            added = PollSpec("341", 0, pkw.read(target.dialect, 341), 0.02)
            s.update_polls(dataclasses.replace(specs[0], polls=(kept, added)))
            assert gone not in s.snapshot.readings
            sent = len(trace.tx)
            others = [("d1", "1614", 0), ("d2", "1613", 0), ("d2", "1614", 0)]
            for _ in range(5):
                await refreshed(s, others)
                assert gone not in s.snapshot.readings
            await until(lambda: ("d1", "341", 0) in s.snapshot.readings)
            assert s.snapshot.readings[("d1", "341", 0)].value == sim.drives[1].value(341)
            await refreshed(s, [*others, ("d1", "341", 0)])
            assert gone not in s.snapshot.readings
            # One on the wire at the update, at most.
            assert (
                trace.tx[sent:].count(
                    SerialCarrier(target).telegram(pkw.read(target.dialect, 1613))
                )
                <= 1
            )
        finally:
            s.stop()
            await asyncio.wait_for(task, 2.0)
    assert gone not in s.snapshot.readings
    assert set(s.snapshot.readings) == {
        ("d1", "1614", 0), ("d1", "341", 0), ("d2", "1613", 0), ("d2", "1614", 0)
    }  # fmt: skip


async def test_a_poll_removed_while_on_the_wire_does_not_land() -> None:
    sim = make_sim("fc", [1, 2], timing=SLOW)
    stamps = counter()
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1, 2], [1613, 1614], 0.0)
        s, _, _ = runner(port, "fc", specs, timeout=1.0, wall_clock=lambda: float(next(stamps)))
        task = asyncio.create_task(s.run())
        gone = ("d1", "1613", 0)
        try:
            await until(lambda: len(s.snapshot.readings) == 4)
            await until(lambda: on_the_wire(s, "d1", "1613"))
            s.update_polls(dataclasses.replace(specs[0], polls=specs[0].polls[1:]))
            assert gone not in s.snapshot.readings
            for _ in range(3):  # recorded in order: its answer before these
                await refreshed(s, [("d1", "1614", 0), ("d2", "1613", 0), ("d2", "1614", 0)])
                assert gone not in s.snapshot.readings
        finally:
            s.stop()
            await asyncio.wait_for(task, 5.0)
    assert gone not in s.snapshot.readings
