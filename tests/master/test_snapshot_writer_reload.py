"""The snapshot's writer across a reload that changes a drive in place: a value is never shown
in a format it was not decoded in; a parameter described before and asked again does not
wait for a description that never comes; an exchange out when its drive was taken away
is not the errors of the drive of its name added since."""

from __future__ import annotations

from dataclasses import replace

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.carriers import carrier_for
from pkwbus.master.events import Exchanged
from pkwbus.master.planning.answers import ErrorKind
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import (
    DescribedAnew,
    DescribeTarget,
    DriveSpec,
    Finished,
    PollSpec,
    Redecoded,
)
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.snapshot_writer import SnapshotWriter
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import DescriptionForm, DriveDescription
from pkwbus.protocol.values import ValueType
from pkwbus.protocol.values.types import Scaling

TARGET = DriveTarget.create("fc", 1)
HZ = ParameterDescription("Frequency", ValueType.U16, Scaling.scale(0.1), "Hz")
RPM = replace(HZ, scaling=Scaling.scale(6.0), unit="rpm")


def poll(pnu: int, fmt: ParameterDescription = HZ, every: float = 1.0) -> PollSpec:
    return PollSpec(f"{pnu // 100}-{pnu % 100:02d}", 0, pkw.read(TARGET.dialect, pnu), every, fmt)


def target(pnu: int) -> DescribeTarget:
    return DescribeTarget(pnu, f"{pnu // 100}-{pnu % 100:02d}", (1, 2, 4, 6))


def spec(
    polls: tuple[PollSpec, ...], describe: tuple[int, ...] = (), *, form: bool = False
) -> DriveSpec:
    return DriveSpec(
        "fan", carrier_for(TARGET), polls, tuple(target(p) for p in describe),
        DescriptionForm.DANFOSS_FC if form else None,
    )  # fmt: skip


def answered(p: PollSpec, raw: int) -> Finished:
    return Finished("fan", p, Answered(pkw.ValueResponse(1, p.request.pnu, 0, raw, pkw.Width.WORD)))


def test_a_kept_poll_decoded_otherwise_now_leaves_its_value_until_its_next_answer() -> None:
    """The drive does not answer (down, in maintenance): raw 400 read at 0.1 Hz is not
    shown as 40 rpm; a poll whose interval alone changed keeps its value."""
    hz, other = poll(1613), poll(1614)
    snapshot = Snapshot()
    writer = SnapshotWriter("l", [spec((hz, other))], snapshot)
    writer.apply([answered(hz, 400), answered(other, 7)])
    assert snapshot.readings[("fan", "16-13", 0)].value == 40
    assert ("fan", 1613, 0) in snapshot.latest
    rpm, slower = poll(1613, RPM), poll(1614, every=5.0)
    writer.update_polls(spec((rpm, slower)), [rpm, slower])
    assert ("fan", "16-13", 0) not in snapshot.readings
    assert ("fan", 1613, 0) not in snapshot.latest  # the writable view shows it too
    assert snapshot.readings[("fan", "16-14", 0)].value == 0.7
    assert snapshot.decoding["fan"].formats[("16-13", 0)] == RPM
    writer.apply([answered(hz, 400)])  # out when the reload came: decoded at 0.1 Hz
    assert ("fan", "16-13", 0) not in snapshot.readings
    assert ("fan", 1613, 0) not in snapshot.latest
    writer.apply([answered(rpm, 400)])
    assert snapshot.readings[("fan", "16-13", 0)].value == 2400
    assert snapshot.latest[("fan", 1613, 0)].value == 2400


def test_a_parameter_asked_again_after_a_reload_took_it_away_does_not_wait() -> None:
    """Its describer keeps what it described (planning.reload): nothing settles it again, so
    it must not be pending; a parameter new to the drive waits, as at a start."""
    p13, p14 = poll(1613), poll(1614)
    snapshot = Snapshot()
    writer = SnapshotWriter("l", [spec((p13, p14), (1613, 1614), form=True)], snapshot)
    decoding = snapshot.decoding["fan"]
    assert decoding.pending == {1613, 1614}
    found = DriveDescription(name="Frequency")
    writer.apply([DescribedAnew("fan", target(p), found, ()) for p in (1613, 1614)])
    assert decoding.pending == set()
    writer.update_polls(spec((p13,), (1613,), form=True), [p13])
    writer.update_polls(spec((p13, p14), (1613, 1614, 341), form=True), [p13, p14])
    assert decoding.pending == {341}  # new: it waits; 16-14 was described


def test_a_parameter_taken_away_before_it_settled_still_waits_when_asked_again() -> None:
    p13 = poll(1613)
    snapshot = Snapshot()
    writer = SnapshotWriter("l", [spec((p13,), (1613, 341), form=True)], snapshot)
    decoding = snapshot.decoding["fan"]
    writer.update_polls(spec((p13,), (1613,), form=True), [p13])
    assert decoding.pending == {1613}  # not asked: no API read of 3-41 waits for it
    writer.update_polls(spec((p13,), (1613, 341), form=True), [p13])
    assert decoding.pending == {1613, 341}  # its describer has not described it yet
    writer.apply([DescribedAnew("fan", target(341), None, (), "refused")])
    assert decoding.pending == {1613}


def test_new_polls_of_a_parameter_described_before_settle_it() -> None:
    p13 = poll(1613)
    snapshot = Snapshot()
    writer = SnapshotWriter("l", [spec((p13,), (1613,), form=True)], snapshot)
    snapshot.decoding["fan"].pending.add(1614)  # however it came to wait
    p14 = poll(1614)
    writer.apply([Redecoded("fan", target(1614), DriveDescription(name="Frequency"), (p14,))])
    assert snapshot.decoding["fan"].pending == {1613}


def test_an_exchange_out_when_its_drive_was_taken_away_is_the_lines_time_alone() -> None:
    """The drive is replaced (same name, another address) while its exchange is out: the
    old one's timeout is not the new one's error; the new one's errors count."""
    snapshot = Snapshot()
    writer = SnapshotWriter("l", [spec((poll(1613),))], snapshot)
    writer.remove_drive("fan", exchange_out=True)
    writer.add_drive(spec((poll(1613),)))
    writer.apply([Exchanged("fan", ErrorKind.TIMEOUT, 0.5)])
    assert snapshot.counts["fan"].errors == 0
    assert snapshot.totals["l"].telegrams == 1 and snapshot.totals["l"].busy == 0.5
    writer.apply([Exchanged("fan", ErrorKind.TIMEOUT, 0.5)])
    assert snapshot.counts["fan"].errors == 1
    writer.remove_drive("fan")  # nothing of it out: the next exchange of its name is new
    writer.add_drive(spec((poll(1613),)))
    writer.apply([Exchanged("fan", ErrorKind.TIMEOUT, 0.5)])
    assert snapshot.counts["fan"].errors == 1
