"""MQTT writes against a real mosquitto with a password file and an ACL, over the service's
real write path (simulated FC drives on TCP, the audit log on disk): an allowed set written,
audited as ``mqtt:{user}`` and answered (to its response topic with its correlation data,
and to the result topic); a set the ACL denies never reaches the drive; a retained set and
an expired set are never executed, and a stored retained set is never delivered again; a
set outside ``writable``, a bad payload and an unknown drive are refused with nothing sent."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiomqtt
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from prometheus_client import CollectorRegistry

from pkwbus.service.audit.log import AuditEntry
from pkwbus.service.mqtt.connection import Connection
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.sets import take_sets
from pkwbus.service.mqtt.writes import SetTopic, SetTopics, parse_set_topic
from tests.service.http.conftest import Service, service
from tests.service.mqtt.broker import USERS, Broker, mosquitto

PREFIX = "pkwbus"
SET = f"{PREFIX}/line_fc/fan1/set"
TIMEOUT = 30.0  # generous: a loaded 2-core machine
PNU_RAMP_UP = 341  # 3-41 Ramp 1 Ramp Up Time, writable in the tests' configuration
PNU_FREQUENCY = 1613  # 16-13 Frequency: polled, not writable


def client(broker: Broker, user: str, name: str) -> aiomqtt.Client:
    return aiomqtt.Client(
        broker.host,
        broker.port,
        username=user,
        password=USERS[user],
        identifier=name,
        protocol=aiomqtt.ProtocolVersion.V5,
    )


@contextlib.asynccontextmanager
async def sets_served(
    broker: Broker, svc: Service, clock: Callable[[], float] | None = None
) -> AsyncIterator[SetTopics]:
    """The service's side: its set topics taken on its broker connection (account
    ``pkwbus``), as ``mqtt.writes: allow_list`` has them."""
    connection = Connection(
        broker.host,
        broker.port,
        username="pkwbus",
        password=USERS["pkwbus"],
        status_topic=f"{PREFIX}/status",
        metrics=MqttMetrics(CollectorRegistry()),
    )
    sets = take_sets(connection, svc.api.writes, PREFIX)
    if clock is not None:
        sets.clock = clock
    connection.start()
    try:
        async with asyncio.timeout(TIMEOUT):
            await connection.connected.wait()
        yield sets
    finally:
        await sets.settled()
        await connection.stop()


@dataclass
class Operator:
    """A client of the plant publishing sets and collecting what comes back."""

    connection: aiomqtt.Client
    seen: list[aiomqtt.Message] = field(default_factory=list)
    arrived: asyncio.Event = field(default_factory=asyncio.Event)

    async def set(
        self,
        user: str,
        parameter: str,
        body: Any,
        *,
        retain: bool = False,
        response_topic: str | None = None,
        correlation: bytes | None = None,
        expiry: int | None = None,
    ) -> None:
        props = Properties(PacketTypes.PUBLISH)  # type: ignore[no-untyped-call]
        if response_topic is not None:
            props.ResponseTopic = response_topic
        if correlation is not None:
            props.CorrelationData = correlation
        if expiry is not None:
            props.MessageExpiryInterval = expiry
        payload = body if isinstance(body, bytes) else json.dumps(body).encode()
        await self.connection.publish(
            f"{SET}/{user}/{parameter}", payload, qos=1, retain=retain, properties=props
        )

    async def result(self, request_id: str | None, topic: str | None = None) -> aiomqtt.Message:
        """The first message on ``topic`` (a result topic by default) for ``request_id``."""

        def match(m: aiomqtt.Message) -> bool:
            if topic is not None and m.topic.value != topic:
                return False
            if topic is None and not m.topic.value.endswith("/result"):
                return False
            return bool(json.loads(m.payload).get("request_id") == request_id)

        return await self.first(match)

    async def first(self, match: Callable[[aiomqtt.Message], bool]) -> aiomqtt.Message:
        async with asyncio.timeout(TIMEOUT):
            while True:
                for m in self.seen:
                    if match(m):
                        return m
                self.arrived.clear()
                await self.arrived.wait()


@contextlib.asynccontextmanager
async def operator(broker: Broker, user: str) -> AsyncIterator[Operator]:
    async with client(broker, user, f"test-{user}") as connection:
        op = Operator(connection)
        await connection.subscribe(f"{PREFIX}/#", qos=1)
        await connection.subscribe(f"replies/{user}/#", qos=1)

        async def collect() -> None:
            async for message in connection.messages:
                op.seen.append(message)
                op.arrived.set()

        task = asyncio.create_task(collect())
        try:
            yield op
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


def payload(message: aiomqtt.Message) -> dict[str, Any]:
    body = json.loads(message.payload)
    assert isinstance(body, dict)
    return body


async def audit_rows(svc: Service) -> list[AuditEntry]:
    assert svc.audit is not None
    return await asyncio.to_thread(svc.audit.latest, 100)


READ_BACK = ("not-writable", "retained", "expired", "extra", "bool", "later", "op2")


def stepping(step: float) -> Callable[[], float]:
    """A clock that moves ``step`` seconds at each reading."""
    ticks: Iterator[int] = itertools.count()
    return lambda: next(ticks) * step


async def test_an_allowed_set_is_written_audited_and_answered(tmp_path: Path) -> None:
    with mosquitto(tmp_path / "broker") as broker:
        async with service(tmp_path) as svc:
            async with sets_served(broker, svc), operator(broker, "op1") as op:
                await op.set(
                    "op1",
                    "3-41",
                    {"value": 12.5, "request_id": "r1"},
                    response_topic="replies/op1/a",
                    correlation=b"\x00corr-1",
                )
                first = await op.result("r1", "replies/op1/a")
                await op.set("op1", "3-41", {"value": 7.25, "store": "ram", "request_id": "r2"})
                second = await op.result("r2")
                value = await op.first(
                    lambda m: (
                        m.topic.value == f"{PREFIX}/line_fc/fan1/value/3-41"
                        and payload(m)["v"] == 7.25
                    )
                )

            assert first.properties is not None
            assert first.properties.CorrelationData == b"\x00corr-1"  # type: ignore[attr-defined]
            answered = payload(first)
            assert answered["outcome"] == "ok", answered
            assert answered["value"] == 12.5 and answered["raw"] == 1250
            assert answered["verified"] is True
            result = payload(second)
            assert second.topic.value == f"{PREFIX}/line_fc/fan1/result"
            assert second.qos == 1
            assert result["outcome"] == "ok" and result["old_value"] == 12.5
            assert payload(value)["raw"] == 725 and payload(value)["unit"] == "s"

            # Both reached the drive, as written, and it holds the last.
            written = [r.value for r in svc.audit_writer.writes(address=1, pnu=PNU_RAMP_UP)]
            assert written == [1250, 725]
            assert svc.sim.drives[1].params.raw[(PNU_RAMP_UP, 0)] == 725
            rows = {r.id: r for r in await audit_rows(svc)}
            row = rows[result["audit_id"]]
            assert (row.client, row.drive, row.parameter) == ("mqtt:op1", "fan1", "3-41")
            assert row.outcome == "ok" and row.token_id is None
            assert rows[answered["audit_id"]].client == "mqtt:op1"


async def test_refused_sets_send_nothing(tmp_path: Path) -> None:
    with mosquitto(tmp_path / "broker") as broker:
        async with service(tmp_path) as svc:
            # Each reading of the clock is 5 s later: a set that expires within 2 s is past
            # its expiry when it would be sent, one of an hour is not.
            async with (
                sets_served(broker, svc, stepping(5)),
                operator(broker, "op1") as op,
                operator(broker, "op2") as op2,
            ):
                # op2 under op1's name: the ACL drops it at the broker.
                await op2.set("op1", "3-41", {"value": 30, "request_id": "denied"})
                await op.set("op1", "16-13", {"value": 5, "request_id": "not-writable"})
                await op.set("op1", "3-41", {"value": 31, "request_id": "retained"}, retain=True)
                await op.set("op1", "3-41", {"value": 32, "request_id": "expired"}, expiry=2)
                await op.set("op1", "3-41", b"value=10")
                await op.set("op1", "3-41", {"value": 33, "request_id": "extra", "force": 1})
                await op.set("op1", "3-41", {"value": True, "request_id": "bool"})
                nowhere = f"{PREFIX}/line_fc/nope/set/op1/3-41"
                await op.connection.publish(nowhere, b'{"value": 1, "request_id": "nope"}', qos=1)
                await op.set("op1", "3-41", {"value": 34, "request_id": "later"}, expiry=3600)
                # op2 as itself may publish; its set comes after the denied one.
                await op2.set("op2", "3-41", {"value": 35, "request_id": "op2"})
                results = {rid: payload(await op.result(rid)) for rid in READ_BACK}
                not_json = payload(await op.result(None))
                unknown = payload(await op.result("nope", f"{PREFIX}/line_fc/nope/result"))

            assert not [m for m in op.seen if b'"denied"' in m.payload]
            assert results["not-writable"]["outcome"] == "refused"
            assert results["not-writable"]["error"]["kind"] == "not_writable"
            assert results["retained"]["outcome"] == "refused"
            assert results["retained"]["error"]["kind"] == "retained"
            assert results["expired"]["outcome"] == "not_sent"
            assert results["expired"]["error"]["kind"] == "expired"
            assert results["bool"]["outcome"] == "invalid"
            assert results["extra"]["outcome"] == "invalid"
            assert "force" in results["extra"]["error"]["message"]
            assert not_json["outcome"] == "invalid" and "not JSON" in not_json["error"]["message"]
            assert unknown["outcome"] == "invalid"
            assert unknown["error"]["kind"] == "unknown_drive"
            assert results["later"]["outcome"] == "ok"
            assert results["op2"]["outcome"] == "ok"

            # Only the two good sets reached the drive: 34 (op1), then 35 (op2).
            assert [r.value for r in svc.audit_writer.writes()] == [3400, 3500]
            assert not svc.audit_writer.writes(pnu=PNU_FREQUENCY)
            rows = await audit_rows(svc)
            by_id = {r.id: r for r in rows}
            for rid in ("not-writable", "retained", "expired", "bool", "extra"):
                row = by_id[results[rid]["audit_id"]]
                assert row.client == "mqtt:op1" and row.outcome == results[rid]["outcome"]
            assert by_id[results["op2"]["audit_id"]].client == "mqtt:op2"
            assert not [r for r in rows if r.new_value in (30, 30.0)]  # the denied set
            assert len(rows) == 9  # 2 written, 7 refused; nothing of the denied set

            # The retained set is still stored by the broker: a new subscription (a
            # reconnect) is never handed it (retain handling 2).
            async with sets_served(broker, svc), operator(broker, "op1") as op:
                await op.set("op1", "3-41", {"value": 36, "request_id": "after"})
                assert payload(await op.result("after"))["outcome"] == "ok"
            assert [r.value for r in svc.audit_writer.writes()] == [3400, 3500, 3600]
            assert len(await audit_rows(svc)) == 10  # the stored retained set: not even seen


def test_set_topics_are_read_after_a_prefix_of_several_levels() -> None:
    found = parse_set_topic("pkwbus/hall-a", "pkwbus/hall-a/l1/fan1/set/op1/3-41/2")
    assert found == SetTopic("l1", "fan1", "op1", "3-41", 2)
    assert parse_set_topic("pkwbus/hall-a", "pkwbus/hall-a/l1/fan1/set/op1/p1082") == SetTopic(
        "l1", "fan1", "op1", "p1082", None
    )
    for other in (
        "pkwbus/hall-b/l1/fan1/set/op1/3-41",  # another site
        "pkwbus/hall-a/l1/fan1/set/op1",  # no parameter
        "pkwbus/hall-a/l1/fan1/set/op1/3-41/256",  # past the last index
        "pkwbus/hall-a/l1/fan1/set/op1/3-41/x",
        "pkwbus/hall-a/l1/fan1/result",
        "pkwbus/hall-a/l1/fan1/set//3-41",  # an empty user
    ):
        assert parse_set_topic("pkwbus/hall-a", other) is None, other


async def test_pkwbus_run_takes_sets_and_is_a_sparkplug_node(tmp_path: Path) -> None:
    """The wiring: ``pkwbus run`` with ``writes: allow_list`` and ``sparkplug:`` answers a
    set and announces its node, on the same broker."""
    from tests.service.mqtt.test_output import plant, run

    with mosquitto(tmp_path / "broker") as broker:
        async with plant() as (sim, url):
            polls = [{"parameter": "16-13", "every": "200ms"}]
            drive = {"name": "fan1", "address": 1, "catalog": "danfoss-fc", "poll": polls,
                     "writable": ["3-41"]}  # fmt: skip
            body = {
                "audit_db": str(tmp_path / "audit.sqlite"),
                "mqtt": {
                    "url": f"mqtt://{broker.host}:{broker.port}",
                    "username_env": "T_MQTT_USER",
                    "password_env": "T_MQTT_PASSWORD",
                    "homeassistant": {"discovery": False},
                    "writes": "allow_list",
                    "sparkplug": {"group_id": "plant", "edge_node_id": "pkwbus1"},
                },
                "lines": [{"name": "line_fc", "port": url, "protocol": "fc",
                           "baudrate": 115200, "timeout": "250ms", "alarms": "off",
                           "settings": "off", "counters": "off", "drives": [drive]}],
            }  # fmt: skip
            path = tmp_path / "pkwbus.yaml"
            path.write_text(json.dumps(body))
            async with operator(broker, "op1") as op, client(broker, "scada", "scada") as scada:
                await scada.subscribe("spBv1.0/plant/NBIRTH/pkwbus1", qos=0)
                async with run(tmp_path, path):
                    await op.first(lambda m: m.topic.value == f"{PREFIX}/line_fc/fan1/status"
                                   and m.payload == b"online")  # fmt: skip
                    async with asyncio.timeout(TIMEOUT):
                        nbirth = await anext(aiter(scada.messages))
                    for attempt in range(100):  # until the drive has described 3-41
                        rid = f"e2e-{attempt}"
                        await op.set("op1", "3-41", {"value": 4.5, "request_id": rid})
                        result = payload(await op.result(rid))
                        if result.get("error", {}).get("kind") != "not_described":
                            break
                        await asyncio.sleep(0.1)
            assert result["outcome"] == "ok" and result["raw"] == 450
            assert sim.drives[1].params.raw[(PNU_RAMP_UP, 0)] == 450
            assert isinstance(nbirth.payload, bytes) and b"Node Control/Rebirth" in nbirth.payload
