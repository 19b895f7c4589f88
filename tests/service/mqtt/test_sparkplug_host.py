"""The edge node and its primary host application (Eclipse Sparkplug 3.0.0, "Edge Node
Session Establishment"), against a real mosquitto over the service's real lines: no
NBIRTH while the host's STATE is offline, births once it is online, an NDEATH and a new
session (``bdSeq`` one more) when it goes offline, births again when it is back; the
``bdSeq`` taken from and kept in its file; the node's messages counted in
``pkwbus_mqtt_messages{kind="sparkplug"}``. And the STATE and ``bdSeq`` file alone."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

from prometheus_client import CollectorRegistry

from pkwbus.service.config.mqtt import mqtt_report
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.sparkplug.host import BdSeqFile, HostState
from pkwbus.service.mqtt.sparkplug.node import SparkplugNode
from tests.service.http.conftest import service
from tests.service.mqtt.broker import USERS, mosquitto
from tests.service.mqtt.test_settings_outbox import config, problems
from tests.service.mqtt.test_sparkplug_node import TIMEOUT, Host, by_name, host

STATE = "spBv1.0/STATE/scada"


async def until(check: object) -> None:
    async with asyncio.timeout(TIMEOUT):
        while not check():  # type: ignore[operator]
            await asyncio.sleep(0.02)


async def state(scada: Host, online: bool, timestamp: int) -> None:
    body = json.dumps({"online": online, "timestamp": timestamp})
    await scada.connection.publish(STATE, body, qos=1, retain=True)


async def test_born_only_while_the_primary_host_is_online(tmp_path: Path) -> None:
    kept = tmp_path / "sparkplug-bdseq"
    kept.write_text("41\n")
    registry = CollectorRegistry()
    metrics = MqttMetrics(registry)
    with mosquitto(tmp_path / "broker") as broker:
        async with service(tmp_path) as svc, host(broker) as scada:
            await state(scada, False, 1000)
            node = SparkplugNode(
                svc.runtime, None, group_id="plant", edge_node_id="pkwbus1",
                host=broker.host, port=broker.port, username="pkwbus", password=USERS["pkwbus"],
                primary_host_id="scada", bd_seq_file=kept, metrics=metrics,
            )  # fmt: skip
            outputs = svc.runtime.outputs
            outputs.swap([*outputs.items, node])
            node.start()
            try:
                # Connected and told the host is offline: nothing published.
                await until(lambda: node.host_state.online is False)
                assert node.bd_seq == 42 and kept.read_text().strip() == "42"
                at = len(scada.seen)
                await state(scada, True, 2000)
                found, nbirth = await scada.first("NBIRTH")
                assert found >= at and not any("/NBIRTH/" in t for t, _ in scada.seen[:at])
                assert by_name(nbirth)["bdSeq"].value == 42 and nbirth.seq == 0
                for drive in ("fan1", "fan2", "fan3"):
                    await scada.first("DBIRTH", drive, found)
                assert metrics.sent["sparkplug"]._value.get() >= 4  # NBIRTH, 3 DBIRTHs

                # A late, older STATE changes nothing; an offline one ends the session.
                await state(scada, False, 1500)
                at = len(scada.seen)
                await state(scada, False, 3000)
                _, death = await scada.first("NDEATH", after=at)
                assert by_name(death)["bdSeq"].value == 42
                # A new session, waiting for the host: bdSeq one more, kept; no birth.
                await until(lambda: node.bd_seq == 43 and node.host_state.online is False)
                assert kept.read_text().strip() == "43"
                at = len(scada.seen)
                await state(scada, True, 4000)
                found, reborn = await scada.first("NBIRTH", after=at)
                assert by_name(reborn)["bdSeq"].value == 43 and reborn.seq == 0
                assert not any("/NBIRTH/" in t for t, _ in scada.seen[at - 1 : found])
            finally:
                await node.stop()


def test_the_newest_state_counts() -> None:
    seen = HostState()
    assert seen.online is None
    assert seen.take(b'{"online": true, "timestamp": 5}') is True
    assert seen.take(b'{"online": false, "timestamp": 4}') is True  # older: ignored
    assert seen.take(b"not json") is True
    assert seen.take(b'{"online": "no", "timestamp": 9}') is True
    assert seen.take(b'{"online": false, "timestamp": 6}') is False


def test_bd_seq_file(tmp_path: Path) -> None:
    kept = BdSeqFile(tmp_path / "bdseq")
    assert kept.last() == -1  # none yet: the first session is 0
    kept.keep(255)
    assert BdSeqFile(tmp_path / "bdseq").last() == 255
    (tmp_path / "bdseq").write_text("garbage")
    assert kept.last() == -1
    assert BdSeqFile(None).last() == -1
    BdSeqFile(tmp_path / "missing" / "bdseq").keep(3)  # logged, not raised
    assert not list(tmp_path.glob("*.tmp"))


def test_check_config_says_what_sparkplug_publishes() -> None:
    node = "  sparkplug: {group_id: plant, edge_node_id: pkwbus1"
    said = list(mqtt_report(config(f"  url: mqtt://broker\n{node}, primary_host_id: scada}}"),
                            [1.0], 3))  # fmt: skip
    assert "spBv1.0/plant/{kind}/pkwbus1" in said[2]
    assert "while the primary host scada is online (spBv1.0/STATE/scada)" in said[2]
    assert "a DBIRTH per answering drive of 3" in said[2]
    assert said[3] == "sparkplug: DCMD not taken"
    alone = list(mqtt_report(config(f"  url: mqtt://broker\n{node}}}"), [1.0], 3))
    assert "NBIRTH at each connection" in alone[2]
    assert len(list(mqtt_report(config("  url: mqtt://broker"), [1.0], 3))) == 2
    bad = problems(f"  url: mqtt://broker\n{node}, primary_host_id: a/b}}")
    assert any("primary_host_id" in p for p in bad), bad
