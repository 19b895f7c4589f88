"""Home Assistant sensors only for what is polled: a default counter that no vendor document
types waits for the drive to describe its type (``PollSpec.described_only``); until then it
has no sensor, and once the drive has described it, the drive is announced again."""

from __future__ import annotations

import json
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from prometheus_client import CollectorRegistry

from pkwbus.master.planning.plan import DescribedAnew, DescribeTarget
from pkwbus.protocol.pkw.descriptions import DATA_TYPES, DriveDescription
from pkwbus.protocol.values.types import ValueType
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.service.config.mqtt import Mqtt
from pkwbus.service.mqtt.connection import Connection
from pkwbus.service.mqtt.discovery import device_config
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.outbox import Outbox
from pkwbus.service.mqtt.output import MqttOutput
from pkwbus.service.mqtt.values import ValueTopics
from pkwbus.service.runtime import Runtime
from tests.service.mqtt.test_values import CONFIG as VALUES_CONFIG

U32 = next(code for code, (_, vtype) in DATA_TYPES.items() if vtype is ValueType.U32)

# test_values' drive, with the default counters (the catalog types none by a vendor document)
CONFIG = VALUES_CONFIG.replace("    counters: off\n", "")


@pytest.fixture
async def runtime(tmp_path: Path) -> AsyncIterator[Runtime]:
    yield await build_runtime(parse_config(CONFIG.format(folder=tmp_path), environ={}))


def sensors(runtime: Runtime) -> set[str]:
    topics = ValueTopics("pkwbus", lambda: runtime.drives, runtime.snapshot)
    payload = json.loads(device_config("pkwbus", runtime.drives["fan"], topics))
    return {s["state_topic"].rsplit("/value/", 1)[1] for s in payload["components"].values()}


async def test_a_counter_waiting_for_its_type_has_a_sensor_once_the_drive_describes_it(
    runtime: Runtime,
) -> None:
    waiting = [p for p in runtime.drives["fan"].polls if p.described_only]
    assert waiting, "the catalog types every default counter now: this test needs another"
    counter = waiting[0]
    assert counter.parameter not in sensors(runtime) and "16-13" in sensors(runtime)
    described = runtime.snapshot.decoding["fan"].described
    described[counter.request.pnu] = DriveDescription(name="NO TYPE")  # described, no type
    assert counter.parameter not in sensors(runtime)
    described[counter.request.pnu] = DriveDescription(type_code=U32, name="TYPED")
    assert counter.parameter in sensors(runtime)


async def test_the_drive_is_announced_again_when_it_describes_such_a_counter(
    runtime: Runtime, tmp_path: Path
) -> None:
    settings = Mqtt.model_validate({"url": "mqtt://127.0.0.1:1"})
    metrics = MqttMetrics(CollectorRegistry())
    connection = Connection("127.0.0.1", 1, username=None, password=None,
                            status_topic="pkwbus/status", metrics=metrics)  # fmt: skip
    outbox = Outbox(tmp_path / "o.sqlite", 1 << 20, 3600.0)
    output = MqttOutput(settings, runtime, connection, outbox, metrics)
    polls = runtime.drives["fan"].polls
    counter = next(p for p in polls if p.described_only)
    plain = next(p for p in polls if not p.described_only)
    target = DescribeTarget(counter.request.pnu, counter.parameter, (0,))
    output.on_events([DescribedAnew("fan", target, None, (plain,))])
    assert output._described == set()  # a poll typed before: nothing new to announce
    output.on_events([DescribedAnew("fan", target, None, (counter,))])
    assert output._described == {"fan"} and output._wake.is_set()
    outbox.close()
