"""The values' fast path against a real mosquitto: a slice handed as one write through
paho's packet queue, and, for a paho without that queue, the public publish per value;
both deliver every message, in order, topic and payload intact."""

from __future__ import annotations

import asyncio
from pathlib import Path

import aiomqtt
import pytest
from prometheus_client import CollectorRegistry

from pkwbus.service.mqtt import connection as module
from pkwbus.service.mqtt.connection import Connection, publish_head
from pkwbus.service.mqtt.metrics import MqttMetrics
from tests.service.mqtt.broker import USERS, mosquitto

TIMEOUT = 30.0


@pytest.mark.parametrize("queue", [module.PACKET_QUEUE, "_no_such_queue"])
async def test_a_slice_arrives_whole_and_in_order(
    tmp_path: Path, queue: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(module, "PACKET_QUEUE", queue)
    sent = [(f"pkwbus/line1/fan{i:03d}/16-13", f'{{"value": {i}.5}}'.encode()) for i in range(300)]
    with mosquitto(tmp_path / "broker") as broker:
        async with aiomqtt.Client(
            broker.host, broker.port, username="scada", password=USERS["scada"],
            protocol=aiomqtt.ProtocolVersion.V5,
        ) as reader:  # fmt: skip
            await reader.subscribe("pkwbus/line1/#", qos=0)
            connection = Connection(
                broker.host, broker.port, username="pkwbus", password=USERS["pkwbus"],
                status_topic="pkwbus/status", metrics=MqttMetrics(CollectorRegistry()),
            )  # fmt: skip
            connection.start()
            try:
                await asyncio.wait_for(connection.connected.wait(), TIMEOUT)
                assert connection.publish_values([(publish_head(t), p) for t, p in sent])
                got: list[tuple[str, bytes]] = []
                async with asyncio.timeout(TIMEOUT):
                    async for message in reader.messages:
                        assert isinstance(message.payload, bytes)
                        got.append((message.topic.value, message.payload))
                        if len(got) == len(sent):
                            break
                assert got == sent
            finally:
                await connection.stop()
