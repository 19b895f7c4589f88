"""A PROFIBUS DP slave is shown down until its wire tells it is in data exchange (a slave
that never gets there - locked to another master, refusing its configuration - is never
shown up); a drive of a serial bus is shown up until it fails."""

from __future__ import annotations

from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.plan import DriveSpec, HealthChanged
from pkwbus.master.planning.planner import Planner
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.snapshot_writer import SnapshotWriter
from pkwbus.master.target import DriveTarget

DP = DriveSpec("slave", carrier_for(DriveTarget.create("profibus", 8, dialect_name="danfoss-pcv")))
FC = DriveSpec("fc", carrier_for(DriveTarget.create("fc", 1)))
ADDED = DriveSpec(
    "added", carrier_for(DriveTarget.create("profibus", 9, dialect_name="danfoss-pcv"))
)


def test_the_planner_shows_a_dp_slave_down_from_the_start_until_it_is_told_up() -> None:
    planner = Planner([DP, FC], poll_deadline=1.0)
    planner.add_drive(ADDED, 0.0)  # a reload adds a slave: down as at the start
    assert not planner.drive("slave").shown_up and not planner.drive("added").shown_up
    assert planner.drive("fc").shown_up
    planner.line_up(0.0)
    planner.told_health("slave", True, "", 1.0)  # in data exchange
    assert planner.drive("slave").shown_up
    assert [(e.drive, e.up) for e in planner.take_events() if isinstance(e, HealthChanged)] == [
        ("slave", True)
    ]


def test_the_snapshot_shows_a_dp_slave_down_from_the_start_and_up_once_told() -> None:
    snapshot = Snapshot()
    writer = SnapshotWriter("line", [DP, FC], snapshot)
    writer.add_drive(ADDED)
    assert not snapshot.drives["slave"].up and not snapshot.drives["added"].up
    assert snapshot.drives["fc"].up
    writer.apply([HealthChanged("slave", True, "")], 1.0)
    assert snapshot.drives["slave"].up
