"""What the sweep of a drive's settings found lands in the read model by the line's stream:
the drive's count of changed settings, and its change told by the snapshot's ``Changes``
(a page asking for the drives changed since its token is given the drive), once a change."""

from __future__ import annotations

from pkwbus.master.carriers import carrier_for
from pkwbus.master.events import SettingsSeen
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.snapshot import SettingsShown, Snapshot
from pkwbus.master.snapshot_writer import SnapshotWriter
from pkwbus.master.target import DriveTarget

TARGET = DriveTarget.create("fc", 1)


def test_settings_seen_land_in_the_read_model_and_mark_the_drive_changed() -> None:
    snap = Snapshot()
    writer = SnapshotWriter("l1", [DriveSpec("fan", carrier_for(TARGET))], snap)
    token = snap.changes.token()
    writer.apply([SettingsSeen("fan", 2, 1000.0)])
    assert snap.settings["fan"] == SettingsShown(2, 1000.0)
    assert snap.changes.since(token) == ["fan"]
    token = snap.changes.token()
    writer.apply([SettingsSeen("fan", 2, 1000.0)])  # as it was: no change told
    assert snap.changes.since(token) == []
    writer.apply([SettingsSeen("fan", None)])  # not swept any more
    assert "fan" not in snap.settings and snap.changes.since(token) == ["fan"]
    writer.apply([SettingsSeen("gone", 1, None)])  # a drive not on the line: nothing
    assert "gone" not in snap.settings
    writer.apply([SettingsSeen("fan", 1, 2000.0)])
    writer.remove_drive("fan")
    assert snap.settings == {}
