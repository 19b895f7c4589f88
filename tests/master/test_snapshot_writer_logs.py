"""What a line tells the log: a refused poll once, then once a day; a drive back at info."""

from __future__ import annotations

import logging

import pytest

from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.outcomes import Answered, Rejected
from pkwbus.master.planning.plan import (
    DescribedAnew,
    DescribeTarget,
    DriveSpec,
    Finished,
    HealthChanged,
    LeftUnanswered,
    PollSpec,
)
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.snapshot_writer import REFUSAL_RETELL, SnapshotWriter
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import DriveDescription

TARGET = DriveTarget.create("fc", 1)
POLL = PollSpec("19-99", 0, pkw.read(TARGET.dialect, 1999), 1.0)
REFUSED = Rejected(0, "Illegal PNU", "illegal PNU")


def record(clock: list[float]) -> SnapshotWriter:
    return SnapshotWriter(
        "l1", [DriveSpec("fan", carrier_for(TARGET), (POLL,))], Snapshot(), clock=lambda: clock[0]
    )


def lines(caplog: pytest.LogCaptureFixture, level: int) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno == level]


def test_a_poll_refused_every_cycle_is_told_once_then_once_a_day(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    clock = [1000.0]
    rec = record(clock)
    for _ in range(50):
        rec.apply([Finished("fan", POLL, REFUSED)])
        clock[0] += 1.0
    told = lines(caplog, logging.WARNING)
    assert told == ["drive fan refuses the poll of 19-99: Illegal PNU"]
    clock[0] = 1000.0 + REFUSAL_RETELL
    rec.apply([Finished("fan", POLL, REFUSED)])
    assert len(lines(caplog, logging.WARNING)) == 2
    assert "still" in lines(caplog, logging.WARNING)[-1]
    answer = pkw.ValueResponse(1, 1999, 0, 5, pkw.Width.WORD)
    rec.apply([Finished("fan", POLL, Answered(answer))])
    assert lines(caplog, logging.INFO)[-1] == "drive fan answers the poll of 19-99 again"


def test_a_drive_that_answers_again_is_told_at_info(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    rec = record([0.0])
    rec.apply([HealthChanged("fan", False, "no answer to 3 exchanges")])
    rec.apply([HealthChanged("fan", True, "answers again")])
    assert lines(caplog, logging.WARNING) == [
        "drive fan is down: no answer to 3 exchanges (probing at back-off)"
    ]
    assert lines(caplog, logging.INFO) == ["drive fan answers again"]


def test_a_drive_silent_on_its_descriptions_is_one_warning_not_one_per_parameter(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    rec = record([0.0])
    why = "no answer to 2 description requests in a row"
    targets = [DescribeTarget(pnu, f"16-{pnu % 100:02d}", (1, 2, 4, 6)) for pnu in (1613, 1614)]
    rec.apply([LeftUnanswered("fan", t, None, (), why) for t in targets])
    assert len(lines(caplog, logging.WARNING)) == 1
    assert why in lines(caplog, logging.WARNING)[0]
    described = DriveDescription(type_code=3, conversion=-1, unit="Hz")
    rec.apply([DescribedAnew("fan", targets[0], described, ())])  # it answers again
    rec.apply([LeftUnanswered("fan", targets[1], None, (), why, first=False)])
    assert len(lines(caplog, logging.WARNING)) == 2  # told again after it had answered


def test_a_writable_parameter_the_drive_calls_read_only_is_told_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    rec = record([0.0])
    writable = DescribeTarget(341, "3-41", (1, 2, 4, 6, 7, 8), writable=True)
    polled = DescribeTarget(1614, "16-14", (1, 2, 4, 6))
    read_only = DriveDescription(type_code=7, conversion=-2, read_only=True)
    rec.apply([DescribedAnew("fan", writable, read_only, ()),
               DescribedAnew("fan", polled, read_only, ())])  # fmt: skip
    told = lines(caplog, logging.WARNING)
    assert len(told) == 1 and "3-41" in told[0] and "read-only" in told[0]
