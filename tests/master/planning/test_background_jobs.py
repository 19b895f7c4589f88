"""Background jobs (the reading of a drive's own log) on a fake clock: never ahead of a
poll that is due, ahead of nothing else, and still done while the line has time."""

from __future__ import annotations

from pkwbus.master.planning.jobs import Job, JobKind, Priority
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import Finished, Overrun, PollSpec
from pkwbus.master.planning.planner import Planner
from pkwbus.protocol import pkw
from pkwbus.sim import SimTiming, Simulator
from tests.master.planning.test_planner import EXCHANGE, MS, FakeLine, drives, fake_line


def background(line_drive: str, request: pkw.PkwRequest, now: float) -> Job:
    return Job(line_drive, request, JobKind.READ, Priority.BACKGROUND, now + 60.0)


def test_background_jobs_wait_for_due_polls_and_polls_keep_their_intervals() -> None:
    line = fake_line("fc", [1, 2], [1613, 1614], 20 * MS)
    line.run(0.2)
    dialect = line.planner.drive("d1").carrier.dialect
    jobs = [background("d1", pkw.read(dialect, 1530, i), line.now) for i in range(10)]
    for job in jobs:
        line.planner.submit(job, line.now)
    start = len(line.sent)
    line.run(2.0)
    done = [e for e in line.events if isinstance(e, Finished) and e.work in jobs]
    assert len(done) == 10 and all(isinstance(e.outcome, Answered) for e in done)
    assert not [e for e in line.events if isinstance(e, Overrun)], "a poll waited for them"
    # Each background read went out at a moment no poll of its drive was due.
    polls_after = [
        e for e in line.events[start:] if isinstance(e, Finished) and isinstance(e.work, PollSpec)
    ]
    assert len(polls_after) >= 2 * 2 * 2.0 / (20 * MS) - 8  # every poll, every 20 ms


def test_a_read_of_the_api_goes_ahead_of_the_background() -> None:
    line = fake_line("fc", [1], [], 1.0)
    dialect = line.planner.drive("d1").carrier.dialect
    for i in range(5):
        line.planner.submit(background("d1", pkw.read(dialect, 1530, i), line.now), line.now)
    asked = line.submit("d1", pkw.read(dialect, 341))
    first = line.step(line.now + 1.0)
    assert first is not None
    finished = [e for e in line.events if isinstance(e, Finished)]
    assert [e.work for e in finished] == [asked]


def test_background_jobs_end_with_the_line() -> None:
    line = fake_line("fc", [1], [], 1.0)
    dialect = line.planner.drive("d1").carrier.dialect
    job = background("d1", pkw.read(dialect, 1530, 0), line.now)
    line.planner.submit(job, line.now)
    line.planner.stop("the service is stopping")
    (done,) = [e for e in line.planner.take_events() if isinstance(e, Finished)]
    assert done.work is job


def test_a_drive_with_background_work_of_its_own_still_polls_when_its_polls_fall_due() -> None:
    """Polls take two thirds of the line; every drive, the polling ones too, always has a
    background read waiting (a sweep of settings faster than the line can carry): a
    drive's claim for its background read must give way to its own poll when that falls
    due, or its polls wait behind the other drives' background reads."""
    every = 9 * EXCHANGE / 0.66  # three drives poll three parameters: 66 % of the line
    quiet = list(range(4, 24))
    specs = drives("fc", [1, 2, 3], [1613, 1614, 1610], every) + drives("fc", quiet, [], every)
    sim = Simulator("fc", list(range(1, 24)), timing=SimTiming(response_delay=0.0), seed=7)
    line = FakeLine(Planner(specs, poll_deadline=0.5), sim)
    dialect = line.planner.drive("d1").carrier.dialect
    waiting: set[Job] = set()
    end = line.now + 5.0
    while line.now < end:
        for a in range(1, 24):  # each drive: a background read waiting, always
            if not any(job.drive == f"d{a}" for job in waiting):
                job = background(f"d{a}", pkw.read(dialect, 341), line.now)
                waiting.add(job)
                line.planner.submit(job, line.now)
        seen = len(line.events)
        line.step(end)
        # The events of this step alone: the earlier ones were taken out already.
        waiting -= {e.work for e in line.events[seen:] if isinstance(e, Finished)}  # type: ignore[misc]
    polls = [e for e in line.events if isinstance(e, Finished) and isinstance(e.work, PollSpec)]
    assert len(polls) >= 9 * 5.0 / every - 9, "every poll, at its interval"
    assert not [e for e in line.events if isinstance(e, Overrun)], "a poll waited for them"
    assert sum(1 for e in line.events if isinstance(e, Finished) and e.work in waiting) == 0
    assert len([e for e in line.events if isinstance(e, Finished)]) > len(polls), "and reads"
