"""The Sparkplug B edge node against a real mosquitto (password file, ACL), over the
service's real lines (simulated FC drives on TCP) and write path: NBIRTH and DBIRTH from
the catalog with aliases and units, DCMD through the write path (a writable parameter
written and its verified value as DDATA, one outside ``writable`` refused with nothing
sent), rebirth on NCMD, DDEATH when a drive is lost or in maintenance and DBIRTH when it
is back, the NDEATH will (with the connection's bdSeq) when the connection dies, seq in
order."""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path

import aiomqtt

from pkwbus.service.mqtt.sparkplug.codec import DataType, Metric, Payload, decode, encode
from pkwbus.service.mqtt.sparkplug.node import CALLER, SparkplugNode
from tests.service.http.conftest import AUTH, service
from tests.service.mqtt.broker import USERS, Broker, mosquitto

BASE = "spBv1.0/plant"
TIMEOUT = 30.0  # generous: a loaded 2-core machine
PNU_RAMP_UP, PNU_FREQUENCY = 341, 1613


@dataclass
class Host:
    """A SCADA host: every Sparkplug message of the group, decoded, in order."""

    connection: aiomqtt.Client
    seen: list[tuple[str, Payload]] = field(default_factory=list)
    arrived: asyncio.Event = field(default_factory=asyncio.Event)

    async def first(
        self, kind: str, device: str | None = None, after: int = 0,
        match: Callable[[Payload], bool] = lambda p: True,
    ) -> tuple[int, Payload]:  # fmt: skip
        """The first message of ``kind`` (of ``device``) from position ``after`` on."""
        topic = f"{BASE}/{kind}/pkwbus1" + (f"/{device}" if device else "")
        async with asyncio.timeout(TIMEOUT):
            while True:
                for i, (t, p) in enumerate(self.seen[after:], after):
                    if t == topic and match(p):
                        return i, p
                self.arrived.clear()
                await self.arrived.wait()

    async def command(self, kind: str, payload: Payload, device: str | None = None) -> None:
        topic = f"{BASE}/{kind}/pkwbus1" + (f"/{device}" if device else "")
        await self.connection.publish(topic, encode(payload), qos=0)


@contextlib.asynccontextmanager
async def host(broker: Broker) -> AsyncIterator[Host]:
    async with aiomqtt.Client(
        broker.host, broker.port, username="scada", password=USERS["scada"],
        identifier="scada", protocol=aiomqtt.ProtocolVersion.V5,
    ) as connection:  # fmt: skip
        found = Host(connection)
        await connection.subscribe(f"{BASE}/#", qos=0)

        async def collect() -> None:
            async for message in connection.messages:
                assert isinstance(message.payload, bytes)
                found.seen.append((message.topic.value, decode(message.payload)))
                found.arrived.set()

        task = asyncio.create_task(collect())
        try:
            yield found
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task


def by_name(payload: Payload) -> dict[str | None, Metric]:
    return {m.name: m for m in payload.metrics}


async def test_births_commands_rebirth_death(tmp_path: Path) -> None:
    with mosquitto(tmp_path / "broker") as broker:
        async with service(tmp_path) as svc, host(broker) as scada:
            node = SparkplugNode(
                svc.runtime, svc.api.writes, group_id="plant", edge_node_id="pkwbus1",
                host=broker.host, port=broker.port, username="pkwbus", password=USERS["pkwbus"],
            )  # fmt: skip
            outputs = svc.runtime.outputs
            outputs.swap([*outputs.items, node])
            node.start()
            try:
                _, nbirth = await scada.first("NBIRTH")
                births = [await scada.first("DBIRTH", d) for d in ("fan1", "fan2", "fan3")]

                node_metrics = by_name(nbirth)
                assert nbirth.seq == 0
                assert node_metrics["bdSeq"].value == 0
                assert node_metrics["Node Control/Rebirth"].value is False
                assert node_metrics["Node Control/Rebirth"].datatype == DataType.BOOLEAN
                assert [p.seq for _, p in births] == [1, 2, 3]
                fan1 = by_name(births[0][1])
                frequency, ramp = fan1["16-13"], fan1["3-41"]
                assert frequency.datatype == DataType.DOUBLE  # u16, conversion -1
                assert frequency.properties["engUnit"].value == "Hz"
                assert isinstance(frequency.value, float)  # polled: it has a value
                assert ramp.properties["engUnit"].value == "s"  # writable, not polled
                aliases = [m.alias for _, p in births for m in p.metrics]
                aliases += [m.alias for m in nbirth.metrics]
                assert len(aliases) == len(set(aliases))  # unique across the node
                for (_, birth), drive in zip(births, ("fan1", "fan2", "fan3"), strict=True):
                    polled = {p.parameter for p in svc.runtime.drives[drive].polls}
                    assert set(by_name(birth)) == polled | {"3-41", "3-42", "1-20", "4-14"}

                # One DCMD: 16-13 (not writable: refused, nothing sent), then 3-41.
                at = len(scada.seen)
                dcmd = Payload(metrics=[
                    Metric(alias=frequency.alias, datatype=DataType.DOUBLE, value=20.0),
                    Metric(alias=ramp.alias, datatype=DataType.DOUBLE, value=12.5),
                ])  # fmt: skip
                await scada.command("DCMD", dcmd, "fan1")
                _, ddata = await scada.first(
                    "DDATA", "fan1", at,
                    lambda p: any(m.alias == ramp.alias for m in p.metrics),
                )  # fmt: skip
                [written] = [m for m in ddata.metrics if m.alias == ramp.alias]
                assert written.value == 12.5 and written.name is None
                assert [r.value for r in svc.audit_writer.writes(pnu=PNU_RAMP_UP)] == [1250]
                assert not svc.audit_writer.writes(pnu=PNU_FREQUENCY)
                assert svc.audit is not None
                rows = await asyncio.to_thread(svc.audit.latest, 10)
                outcomes = {(r.client, r.parameter, r.outcome) for r in rows}
                assert outcomes == {(CALLER, "16-13", "refused"), (CALLER, "3-41", "ok")}

                # Rebirth: the births again, the same bdSeq, seq from 0.
                at = len(scada.seen)
                rebirth = Metric("Node Control/Rebirth", datatype=DataType.BOOLEAN, value=True)
                await scada.command("NCMD", Payload(metrics=[rebirth]))
                again_at, again = await scada.first("NBIRTH", after=at)
                assert again.seq == 0 and by_name(again)["bdSeq"].value == 0
                _, fan3 = await scada.first("DBIRTH", "fan3", again_at)
                assert fan3.seq == 3

                # fan2 lost, then back.
                at = len(scada.seen)
                svc.sim.kill(2)
                await scada.first("DDEATH", "fan2", at)
                svc.sim.revive(2)
                await scada.first("DBIRTH", "fan2", at)
                # fan3 in maintenance, then out of it.
                url = "/api/v1/drives/fan3/maintenance"
                r = await svc.client.put(url, json={"on": True}, headers=AUTH)
                assert r.status_code == 200, r.text
                await scada.first("DDEATH", "fan3", at)
                r = await svc.client.put(url, json={"on": False}, headers=AUTH)
                assert r.status_code == 200, r.text
                await scada.first("DBIRTH", "fan3", at)
                ours = [p.seq for t, p in scada.seen[again_at:] if "/NDEATH/" not in t]
                assert ours == [n % 256 for n in range(len(ours))]

                # The connection dies without a DISCONNECT: the broker sends the will.
                at = len(scada.seen)
                assert node.client is not None
                sock = node.client._client.socket()
                assert isinstance(sock, socket.socket)
                sock.shutdown(socket.SHUT_RDWR)
                _, death = await scada.first("NDEATH", after=at)
                assert death.seq is None and by_name(death)["bdSeq"].value == 0
                _, reborn = await scada.first("NBIRTH", after=at)
                assert by_name(reborn)["bdSeq"].value == 1 and reborn.seq == 0
            finally:
                await node.stop()
