"""The values' topics, payloads and quality, from a runtime built as `pkwbus run` builds
it (no line running) and a read model set by hand; the deadband; and what the observer
path notes (nothing published, no broker)."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from prometheus_client import CollectorRegistry

from pkwbus.master.events import HealthChanged, MaintenanceChanged, ValueLanded
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import DriveState, Maintained
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.service.config.mqtt import Mqtt
from pkwbus.service.mqtt.connection import Connection, _fixed_header, publish_head
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.outbox import Outbox
from pkwbus.service.mqtt.output import MqttOutput
from pkwbus.service.mqtt.values import ValueTopic, ValueTopics, quality, stale_after
from pkwbus.service.runtime import Runtime

CONFIG = """
audit_db: {folder}/audit.sqlite
lines:
  - name: hall
    port: /dev/pkwbus-test-no-port
    protocol: fc
    baudrate: 115200
    alarms: off
    counters: off
    drives:
      - name: fan
        address: 1
        catalog: danfoss-fc
        poll:
          - {{parameter: "16-13", every: 1s}}
          - {{parameter: "15-30", index: 2, every: 10s}}
          - {{parameter: "16-14", index: 1, every: 1s}}
"""


@pytest.fixture
async def runtime(tmp_path: Path) -> AsyncIterator[Runtime]:
    found = await build_runtime(parse_config(CONFIG.format(folder=tmp_path), environ={}))
    yield found


def test_stale_after_is_the_status_pages_rule() -> None:
    assert stale_after(1.0) == 11.0
    assert stale_after(60.0) == 120.0


async def test_topics_name_the_index_where_it_tells(runtime: Runtime) -> None:
    topics = ValueTopics("pkwbus/site", lambda: runtime.drives, runtime.snapshot)
    plain = topics.get(("fan", "16-13", 0))
    array = topics.get(("fan", "15-30", 2))
    indexed = topics.get(("fan", "16-14", 1))
    assert plain is not None and plain.topic == "pkwbus/site/hall/fan/value/16-13"
    assert array is not None and array.topic == "pkwbus/site/hall/fan/value/15-30/2"
    assert indexed is not None and indexed.topic == "pkwbus/site/hall/fan/value/16-14/1"
    assert topics.get(("fan", "16-99", 0)) is None  # not polled
    assert topics.get(("gone", "16-13", 0)) is None
    payload = json.loads(plain.payload(Reading(50.3, 503, 1_790_000_000.123), "good"))
    assert payload == {"v": 50.3, "raw": 503, "unit": "Hz", "ts": 1_790_000_000_123, "q": "good"}
    assert json.loads(plain.payload(Reading(float("nan"), None, 1.0), "stale"))["v"] is None


async def test_quality_as_the_read_model_says(runtime: Runtime) -> None:
    snap, now = runtime.snapshot, 1_790_000_100.0
    fresh, old = Reading(1.0, 10, now - 5.0), Reading(1.0, 10, now - 12.0)
    snap.drives["fan"] = DriveState(up=True)
    assert quality(snap, "fan", fresh, 1.0, now) == "good"
    assert quality(snap, "fan", old, 1.0, now) == "stale"  # over 11 s for a 1 s poll
    assert quality(snap, "fan", old, 10.0, now) == "good"  # within 20 s for a 10 s poll
    snap.drives["fan"] = DriveState(up=False)
    assert quality(snap, "fan", fresh, 1.0, now) == "offline"
    snap.maintenance["fan"] = Maintained("repair", now)
    assert quality(snap, "fan", fresh, 1.0, now) == "maintenance"


def test_the_deadband() -> None:
    topic = ValueTopic("fan", "t", '"Hz"', 1.0)
    assert topic.changed(50.0, 0.5)  # the first
    topic.last = 50.0
    assert not topic.changed(50.4, 0.5)
    assert not topic.changed(49.5, 0.5)
    assert topic.changed(50.6, 0.5)
    assert topic.changed(50.1, 0.0) and not topic.changed(50.0, 0.0)
    topic.last = "run"
    assert topic.changed("stop", 5.0) and not topic.changed("run", 5.0)


async def test_the_deadband_holds_back_no_change_of_a_code_or_a_word(runtime: Runtime) -> None:
    """15-30 (the alarm log's codes, no unit in the catalog) is published on any change
    whatever the deadband (given in a value's unit, it would hold an alarm back until the
    heartbeat); 16-13 (Hz) keeps its deadband."""
    topics = ValueTopics("pkwbus", lambda: runtime.drives, runtime.snapshot)
    code, frequency = topics.get(("fan", "15-30", 2)), topics.get(("fan", "16-13", 0))
    assert code is not None and frequency is not None
    assert (code.unit, frequency.unit) == ('""', '"Hz"')  # as the catalog gives them
    code.last, frequency.last = 4, 50.0
    assert code.changed(5, 1.0) and not code.changed(4, 1.0)
    assert not frequency.changed(50.5, 1.0) and frequency.changed(51.5, 1.0)


async def test_the_observer_path_only_notes(runtime: Runtime, tmp_path: Path) -> None:
    settings = Mqtt.model_validate({"url": "mqtt://127.0.0.1:1", "values": {"heartbeat": "1m"}})
    metrics = MqttMetrics(CollectorRegistry())
    connection = Connection("127.0.0.1", 1, username=None, password=None,
                            status_topic="pkwbus/status", metrics=metrics)  # fmt: skip
    outbox = Outbox(tmp_path / "o.sqlite", 1 << 20, 3600.0)
    output = MqttOutput(settings, runtime, connection, outbox, metrics)
    a, b = Reading(1.0, 10, 1.0), Reading(2.0, 20, 2.0)
    key = ("fan", "16-13", 0)
    output.on_events([ValueLanded(key, a), HealthChanged("fan", True),
                      ValueLanded(key, b), MaintenanceChanged("fan", True)])  # fmt: skip
    assert output._pending == {("fan", "16-13", 0): b}  # the latest wins
    assert output._statuses == {"fan"}
    assert output._wake.is_set()
    # Not connected: the task drops the values, counted; nothing is kept.
    await output._publish_values(dict(output._pending))
    assert metrics.drops["value"]._value.get() == 1
    outbox.close()


@pytest.mark.parametrize(
    ("remaining", "encoded"),
    # MQTT Version 5.0 (OASIS), 1.5.5 Variable Byte Integer: the table's boundaries.
    [(0, b"\x00"), (127, b"\x7f"), (128, b"\x80\x01"), (16_383, b"\xff\x7f"),
     (16_384, b"\x80\x80\x01"), (2_097_151, b"\xff\xff\x7f"), (2_097_152, b"\x80\x80\x80\x01")],
)  # fmt: skip
def test_a_publish_packets_length_as_the_specification_writes_it(
    remaining: int, encoded: bytes
) -> None:
    assert _fixed_header(remaining) == b"\x30" + encoded


def test_a_publish_head_is_the_topic_and_no_properties() -> None:
    assert publish_head("a/b") == b"\x00\x03a/b\x00"
    assert publish_head("pkwbus/ü") == b"\x00\x09pkwbus/\xc3\xbc\x00"
