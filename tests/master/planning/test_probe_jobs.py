"""A probe job on a fake clock: is a drive there, and what is its status word (a scan's and a
configuration check's question), by the planner like every job."""

from __future__ import annotations

from pkwbus.master.carriers import SerialCarrier, carrier_for
from pkwbus.master.planning.answers import ErrorKind, Failure
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.jobs import JobKind, ProbeJob
from pkwbus.master.planning.outcomes import Heard, LineFailed, NotSent, TimedOut
from pkwbus.master.planning.plan import DriveSpec, Finished, HealthChanged, Send
from pkwbus.master.planning.planner import Planner
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pzd
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.serial.telegram import Telegram, split_block
from pkwbus.sim import SimTiming, Simulator
from tests.master.planning.test_planner import FakeLine

ASKED_ONLY = HealthPolicy(from_answers=False)  # as a command's session asks


def line_of(protocol: str, addresses: list[int], present: list[int], retries: int) -> FakeLine:
    sim = Simulator(protocol, present, timing=SimTiming(response_delay=0.0), seed=7)
    specs = [DriveSpec(f"d{a}", carrier_for(DriveTarget.create(protocol, a))) for a in addresses]
    planner = Planner(specs, poll_deadline=0.5, retries=retries, policy=ASKED_ONLY)
    return FakeLine(planner, sim)


def probe(line: FakeLine, drive: str, within: float = 5.0) -> Finished:
    job = ProbeJob(drive, line.now + within)
    line.planner.submit(job, line.now)
    for _ in range(100):
        done = [e for e in line.events if isinstance(e, Finished) and e.work is job]
        if done:
            (finished,) = done
            return finished
        line.step(job.deadline)
    raise AssertionError("the probe job never finished")


def test_a_drive_that_answers_is_heard_with_its_status_word() -> None:
    for protocol in ("fc", "uss"):
        line = line_of(protocol, [3], [3], retries=2)
        done = probe(line, "d3")
        assert isinstance(done.outcome, Heard), (protocol, done.outcome)
        assert done.tally is not None and done.tally.telegrams == 1
        assert done.tally.status_word == line.sim.drives[3].status_word
        (sent,) = line.sent
        request = next(
            e for e in line.sim.deframer().feed(sent.telegram) if isinstance(e, Telegram)
        )
        if protocol == "fc":
            # The FC probe is the process data alone: no parameter channel is asked (Danfoss
            # FC protocol, the telegram's PCD block), the control word never takes control.
            shape = SerialCarrier(DriveTarget.create("fc", 3)).response_shape(len(request.data))
            block = split_block(request.data, shape)
            assert block.pkw == b"" and not pzd.takes_control(block.pzd[0])
        assert request.adr == SerialCarrier(DriveTarget.create(protocol, 3)).address


def test_an_empty_address_is_asked_retries_plus_one_times_then_left_alone() -> None:
    line = line_of("fc", [3, 4], [4], retries=2)
    done = probe(line, "d3")
    assert isinstance(done.outcome, TimedOut) and "after 3 tries" in done.outcome.reason
    assert done.tally is not None and done.tally.telegrams == 3 and done.tally.retries == 2
    assert [s.drive for s in line.sent] == ["d3"] * 3
    # Not taken down and probed at back-off behind the command's back: nothing more goes out.
    line.run(120.0)
    assert len(line.sent) == 3
    assert not [e for e in line.events if isinstance(e, HealthChanged)]
    assert isinstance(probe(line, "d4").outcome, Heard)


def test_a_probe_ends_at_once_when_the_port_is_gone() -> None:
    line = line_of("fc", [3], [3], retries=2)
    job = ProbeJob("d3", line.now + 5)
    line.planner.submit(job, line.now)
    send = line.planner.next_action(line.now)
    assert isinstance(send, Send) and send.probe
    line.planner.exchanged(send, Failure(ErrorKind.PORT, "the port was lost"), line.now)
    (done,) = [e for e in line.planner.take_events() if isinstance(e, Finished)]
    assert isinstance(done.outcome, LineFailed) and done.work.kind is JobKind.PROBE


def test_a_drive_whose_bus_tells_its_presence_is_not_probed() -> None:
    target = DriveTarget.create(Bus.PROFIBUS, 8)
    planner = Planner([DriveSpec("s8", carrier_for(target))], poll_deadline=1.0, policy=ASKED_ONLY)
    planner.line_up(0.0)
    planner.submit(ProbeJob("s8", 5.0), 0.0)
    assert planner.next_for("s8", 0.0) is None
    (done,) = [e for e in planner.take_events() if isinstance(e, Finished)]
    assert isinstance(done.outcome, NotSent)
