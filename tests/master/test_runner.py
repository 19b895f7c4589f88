"""The line runner end to end over simulated drives: snapshot, lines apart, errors, outages.

The policy itself (order, fairness, health, interleaving, overruns) is the
planner's, tested on a fake clock in test_planner.py.
"""

from __future__ import annotations

import asyncio
import itertools
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any

import pytest

from pkwbus.link import PortSettings
from pkwbus.master.carriers import carrier_for
from pkwbus.master.events import Event, Exchanged, JobDone, Overrun
from pkwbus.master.planning.answers import ErrorKind
from pkwbus.master.planning.jobs import Cancelled, Job, JobKind, JobResult, Priority
from pkwbus.master.planning.outcomes import Answered, LineFailed
from pkwbus.master.planning.plan import DriveSpec, PollSpec
from pkwbus.master.runner import LineRunner
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.sim import SimTiming
from tests.master.conftest import Trace, make_sim, serve, until


class Recorder:
    """An observer of the line's stream that keeps what happened, per drive."""

    def __init__(self) -> None:
        self.exchanges: list[tuple[str, ErrorKind | None]] = []
        self.busy: Counter[str] = Counter()
        self.done: list[tuple[str, JobKind, JobResult]] = []
        self.overruns: Counter[str] = Counter()
        self.batches = 0  # batches of events told so far

    def on_events(self, events: Sequence[Event]) -> None:
        self.batches += 1
        for event in events:
            if isinstance(event, Exchanged):
                self.exchanges.append((event.drive, event.error))
                self.busy[event.drive] += event.busy
            elif isinstance(event, JobDone):
                self.job_finished(event.drive, event.kind, event.result)
            elif isinstance(event, Overrun):
                self.overruns[event.drive] += 1

    def job_finished(self, drive: str, kind: JobKind, result: JobResult) -> None:
        self.done.append((drive, kind, result))

    def polls_ok(self, drive: str) -> int:
        return sum(
            1
            for d, kind, r in self.done
            if d == drive and kind is JobKind.READ and isinstance(r.outcome, Answered)
        )


def drive_specs(
    protocol: str, addresses: list[int], pnus: list[int], every: float
) -> list[DriveSpec]:
    specs = []
    for a in addresses:
        target = DriveTarget.create(protocol, a)
        polls = tuple(PollSpec(str(p), 0, pkw.read(target.dialect, p), every) for p in pnus)
        specs.append(DriveSpec(f"d{a}", carrier_for(target), polls))
    return specs


def runner(
    port: str, protocol: str, specs: list[DriveSpec], *, timeout: float = 0.03, **kw: Any
) -> tuple[LineRunner, Recorder, Trace]:
    trace = Trace()
    line = TelegramPort(
        PortSettings(port, baudrate=115200), Bus(protocol), timeout=timeout, trace=trace
    )
    events = Recorder()
    wire = ExchangeWire(line.timeout)
    return LineRunner("line1", line, wire, specs, observers=[events], **kw), events, trace


async def run_until(s: LineRunner, check: Callable[[], bool]) -> None:
    task = asyncio.create_task(s.run())
    try:
        await until(check)
    finally:
        s.stop()
        await asyncio.wait_for(task, 2.0)


async def test_polls_reach_the_snapshot_with_the_drives_values() -> None:
    sim = make_sim("fc", [1, 2])
    async with serve(sim, "tcp") as port:
        s, events, _ = runner(port, "fc", drive_specs("fc", [1, 2], [341, 1530], 0.05))
        await run_until(s, lambda: all(events.polls_ok(f"d{a}") >= 4 for a in (1, 2)))
    for a in (1, 2):
        reading = s.snapshot.readings[(f"d{a}", "341", 0)]
        assert reading.value == sim.drives[a].value(341)
        assert events.polls_ok(f"d{a}") >= 4
    assert all(state.up for state in s.snapshot.drives.values())
    assert s.snapshot.drives["d1"].status_word == sim.drives[1].status_word


async def test_two_lines_one_failing() -> None:
    sim = make_sim("fc", [1])
    async with serve(sim, "tcp") as port:
        good, good_events, _ = runner(port, "fc", drive_specs("fc", [1], [1613], 0.01))
        bad_line = TelegramPort(PortSettings("socket://127.0.0.1:1", reopen_initial=0.05), Bus.FC)
        bad_specs = drive_specs("fc", [1], [1613], 0.01)
        bad = LineRunner("line2", bad_line, ExchangeWire(bad_line.timeout), bad_specs)
        tasks = [asyncio.create_task(x.run()) for x in (good, bad)]
        await until(
            lambda: (
                good_events.polls_ok("d1") >= 10 and bad_line.link.reconnect.last_error is not None
            )
        )
        for x in (good, bad):
            x.stop()
        await asyncio.gather(*tasks)
    assert good_events.polls_ok("d1") >= 10
    assert good.snapshot.lines["line1"] is False  # closed at stop
    assert (
        bad_line.link.reconnect.last_error and "cannot open" in bad_line.link.reconnect.last_error
    )


async def test_stop_cancels_queued_jobs_and_returns() -> None:
    sim = make_sim("fc", [1], timing=SimTiming(response_delay=0.05))
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1], [1613], 1.0)
        s, _, _ = runner(port, "fc", specs, timeout=0.2)
        task = asyncio.create_task(s.run())
        await asyncio.sleep(0.02)
        loop = asyncio.get_running_loop()
        futures = []
        for _ in range(3):
            f: asyncio.Future[JobResult] = loop.create_future()
            req = pkw.read(specs[0].carrier.dialect, 1614)
            s.submit(Job("d1", req, JobKind.READ, Priority.READ, loop.time() + 5, future=f))
            futures.append(f)
        s.stop()
        await asyncio.wait_for(task, 1.0)
    results = [f.result() for f in futures]
    assert any(isinstance(r.outcome, Cancelled) for r in results)
    assert all(f.done() for f in futures)


async def test_an_unexpected_error_does_not_stop_the_line(caplog: pytest.LogCaptureFixture) -> None:
    sim = make_sim("fc", [1])
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1], [1613], 0.01)
        s, events, _ = runner(port, "fc", specs)
        line: Any = s.port
        real = line.start
        calls = 0

        def flaky(*args: Any, **kw: Any) -> None:
            nonlocal calls
            calls += 1
            if calls == 5:
                raise RuntimeError("something nobody expected")
            real(*args, **kw)

        line.start = flaky
        # the port is reopened after 0.5 s
        await run_until(s, lambda: calls > 10 and events.polls_ok("d1") >= 5)
    assert calls > 10, "the line went on after the error"
    assert events.polls_ok("d1") >= 5
    assert any("unexpected error" in r.getMessage() for r in caplog.records)


async def test_a_port_outage_fails_jobs_in_flight_and_marks_drives_unknown() -> None:
    """Nothing waits for a lost port: the write in flight fails at once and is not
    sent again when the port returns; drives read as down while their line is."""
    timing = SimTiming(response_delay=0.0, lag_telegrams=1000, lag_mode="none")
    sim = make_sim("uss", [1, 2], timing=timing)
    server = await sim.serve_tcp("127.0.0.1", 0)
    port = server.url
    specs = drive_specs("uss", [1, 2], [1120], 0.05)
    trace = Trace()
    line = TelegramPort(
        PortSettings(port, reopen_initial=0.1, reopen_cap=0.2),
        Bus.USS,
        timeout=0.05,
        trace=trace,
    )
    s = LineRunner("line1", line, ExchangeWire(line.timeout), specs, observers=[Recorder()])
    task = asyncio.create_task(s.run())
    loop = asyncio.get_running_loop()
    try:
        await asyncio.sleep(0.2)
        target = specs[0].carrier
        write = pkw.write(target.dialect, 1121, 0x41200000, pkw.Width.DWORD)
        future: asyncio.Future[JobResult] = loop.create_future()
        s.submit(Job("d1", write, JobKind.WRITE, Priority.WRITE, loop.time() + 30, future=future))
        await asyncio.sleep(0.2)  # the write lags: it is in flight, repeated
        assert not future.done()
        await server.close()
        result = await asyncio.wait_for(future, 2.0)
        assert isinstance(result.outcome, LineFailed)
        await asyncio.sleep(0.1)
        assert s.snapshot.drives["d1"].up is False and s.snapshot.lines["line1"] is False
        sent_before = len(trace.tx)
        server = await sim.serve_tcp("127.0.0.1", int(port.rsplit(":", 1)[1]))
        # back up, and polls sent since: a write sent again would have gone first
        await until(lambda: s.snapshot.lines["line1"] and len(trace.tx) >= sent_before + 4)
        assert s.snapshot.lines["line1"] is True
        assert target.telegram(write) not in trace.tx[sent_before:]
    finally:
        s.stop()
        await asyncio.wait_for(task, 2.0)
        await server.close()


async def test_polls_are_recorded_in_batches_each_with_its_own_time_and_none_lost() -> None:
    """During a run, polls and counters are recorded in batches; each reading keeps
    the time of its own exchange, and at the stop everything sent has been recorded."""
    sim = make_sim("fc", [1, 2])
    stamps = itertools.count(1000)
    async with serve(sim, "tcp") as port:
        s, events, trace = runner(
            port, "fc", drive_specs("fc", [1, 2], [1613, 1614], 0.0),
            wall_clock=lambda: float(next(stamps)),
        )  # fmt: skip
        seen: list[int] = []  # the batch each finished poll was recorded in
        job_finished = events.job_finished

        def record(drive: str, kind: JobKind, result: JobResult) -> None:
            seen.append(events.batches)
            job_finished(drive, kind, result)

        events.job_finished = record  # type: ignore[method-assign]
        await run_until(s, lambda: events.polls_ok("d1") >= 20 and events.polls_ok("d2") >= 20)
    assert max(Counter(seen).values()) > 1, "some polls were recorded together"
    assert len(events.exchanges) == len(trace.tx), "every exchange was counted at the stop"
    times = [r.timestamp for r in s.snapshot.readings.values()]
    assert len(times) == 4 and all(t >= 1000 for t in times)
    assert len(set(times)) == 4, "each reading has its own exchange's time, not its batch's"


async def test_a_job_is_recorded_at_once_however_long_a_batch_may_last() -> None:
    sim = make_sim("fc", [1])
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1], [1613], 0.0)
        s, events, trace = runner(port, "fc", specs, batch_every=3600.0)
        task = asyncio.create_task(s.run())
        try:
            await until(lambda: len(trace.tx) >= 5)
            assert not s.snapshot.readings, "the polls wait for their batch"
            loop = asyncio.get_running_loop()
            future: asyncio.Future[JobResult] = loop.create_future()
            request = pkw.read(specs[0].carrier.dialect, 341)
            s.submit(
                Job("d1", request, JobKind.READ, Priority.READ, loop.time() + 5, future=future)
            )
            result = await asyncio.wait_for(future, 5.0)
            assert isinstance(result.outcome, Answered)
            assert result.value == sim.drives[1].value(341)
            assert ("d1", JobKind.READ, result) in events.done
        finally:
            s.stop()
            await asyncio.wait_for(task, 2.0)


async def test_a_batch_is_recorded_at_its_time_while_a_slow_exchange_is_out() -> None:
    """The batch's deadline is a timer: a value is in the snapshot while the next
    exchange still waits for its (slow) answer, not only when that answer comes."""
    sim = make_sim("fc", [1], timing=SimTiming(response_delay=1.0))
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1], [1613], 0.0)
        s, _, trace = runner(port, "fc", specs, timeout=3.0, batch_every=0.05)
        task = asyncio.create_task(s.run())
        try:
            await until(lambda: bool(s.snapshot.readings))
            assert len(trace.rx) == 1, "recorded before the second answer came"
            assert len(trace.tx) == 2
        finally:
            s.stop()
            await asyncio.wait_for(task, 5.0)


async def test_a_drive_going_down_is_recorded_at_once_however_long_a_batch_may_last() -> None:
    sim = make_sim("fc", [1])  # drive 2 never answers
    async with serve(sim, "tcp") as port:
        specs = drive_specs("fc", [1, 2], [1613], 0.0)  # drive 1 always due: no idle end
        s, events, _ = runner(port, "fc", specs, batch_every=3600.0)
        task = asyncio.create_task(s.run())
        try:
            # drive 1 is always due, so the run never ends: only an at-once record shows it
            await until(lambda: s.snapshot.drives["d2"].up is False)
        finally:
            s.stop()
            await asyncio.wait_for(task, 2.0)
    assert events.polls_ok("d1") > 0  # recorded at the stop
