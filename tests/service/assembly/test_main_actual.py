"""pkwbus_drive_main_actual_percent: the second PZD word of a reply, 0x4000 = 100 %.

It goes with the status word: no sample before a drive sent one, none for a
drive whose replies carry a status word only, and kept (like the status word)
while the drive is down. Both renderers of /metrics give the same text.
"""

from __future__ import annotations

import asyncio

from prometheus_client import generate_latest
from prometheus_client.parser import text_string_to_metric_families

from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.plan import DriveSpec, HealthChanged, StatusWord
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.snapshot_writer import SnapshotWriter
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pzd
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.dialects import FC, IndLayout
from pkwbus.protocol.pzd import Profile
from pkwbus.protocol.serial.telegram import FC_PROCESS, BlockShape, split_block
from pkwbus.service.metrics.devices import DriveInfo, SnapshotCollector
from pkwbus.service.metrics.exposition import MetricsRegistry, render

MAV = "pkwbus_drive_main_actual_percent"
WORD = "pkwbus_drive_status_word"


def exported(registry: MetricsRegistry) -> dict[tuple[str, str], float]:
    """(metric, drive) -> value of the drive families, after checking both renderers agree."""
    text = asyncio.run(render(registry)).decode()
    assert text == generate_latest(registry).decode()
    return {
        (s.name, s.labels["drive"]): s.value
        for family in text_string_to_metric_families(text)
        for s in family.samples
        if s.name in (MAV, WORD, "pkwbus_drive_up")
    }


def plant(drives: list[str]) -> tuple[MetricsRegistry, SnapshotWriter]:
    registry = MetricsRegistry()
    snapshot = Snapshot()
    specs = [
        DriveSpec(d, carrier_for(DriveTarget(Bus.FC, i + 1, FC, IndLayout.USS, FC_PROCESS)))
        for i, d in enumerate(drives)
    ]
    record = SnapshotWriter("l1", specs, snapshot)
    infos = {d: DriveInfo("l1", Profile.FC) for d in drives}
    registry.register(SnapshotCollector(snapshot, infos, []))
    return registry, record


def test_the_main_actual_value_comes_with_the_status_word_and_stays_while_down() -> None:
    registry, record = plant(["a", "b", "c"])
    got = exported(registry)
    assert (MAV, "a") not in got and (WORD, "a") not in got  # nothing received yet
    record.apply([
        StatusWord("a", 0x0F07, 0x2000),
        StatusWord("b", 0x0F07, 0xC000),  # two's complement: -0x4000
        StatusWord("c", 0x0F07),  # a reply with one PZD word: no main actual value
    ])  # fmt: skip
    got = exported(registry)
    assert got[(MAV, "a")] == pzd.ref_to_percent(0x2000) == 50.0
    assert got[(MAV, "b")] == pzd.ref_to_percent(0xC000) == -100.0
    assert (MAV, "c") not in got and got[(WORD, "c")] == 0x0F07
    record.apply([HealthChanged("a", False, "timeout")])
    got = exported(registry)
    assert got[("pkwbus_drive_up", "a")] == 0.0
    # Down: the latest status word and main actual value stay, as they came.
    assert got[(WORD, "a")] == 0x0F07 and got[(MAV, "a")] == 50.0
    record.apply([StatusWord("a", 0x0F07, 0x1000)])
    assert exported(registry)[(MAV, "a")] == 25.0


def test_a_replys_second_pzd_word_is_its_main_actual_value() -> None:
    assert split_block(bytes.fromhex("0f07 3333"), FC_PROCESS).main_actual == 0x3333
    one = split_block(bytes.fromhex("0f07"), BlockShape(0, 1))
    assert one.status_word == 0x0F07 and one.main_actual is None
