"""pkwbus as a Sparkplug B edge node (Eclipse Sparkplug 3.0.0), each drive a device.

Topics under ``spBv1.0/{group_id}``: ``NBIRTH``/``NDEATH``/``NCMD`` ``/{edge_node_id}``,
``DBIRTH``/``DDATA``/``DDEATH``/``DCMD`` ``/{edge_node_id}/{drive}``. The node has a
connection of its own (MQTT 5, clean start), whose will is the NDEATH with this
connection's ``bdSeq`` (QoS 1, not retained; 0 at the first connection, one more at
each, 255 then 0); once connected it publishes the NBIRTH (``bdSeq``, ``Node
Control/Rebirth`` false, ``seq`` 0) and a DBIRTH per drive that answers, its metrics
with names, aliases, datatypes and units (:mod:`.metrics`) and their latest values.
Then DDATA by exception: a polled value that changed, by alias, with the time the drive
answered. A drive lost is a DDEATH; back, a DBIRTH. An NCMD ``Node Control/Rebirth``
true publishes the births again (same ``bdSeq``, ``seq`` from 0). Every message but the
NDEATH carries ``seq``, one more each time, 255 then 0; all at QoS 0, not retained.

With writes on (``mqtt.writes: allow_list``) a DCMD's metrics are written through the
one write path (:mod:`.commands`). The broker's ACL says who may publish DCMD (the
primary host's account).

The ``bdSeq`` goes on across restarts (kept in a file, :mod:`.host`). With a primary
host application (``primary_host_id``) the node subscribes to its STATE and is born only
while it is online; its offline ends the session (NDEATH, disconnect), and the node
waits, connected again, for it to come back (Eclipse Sparkplug 3.0.0, "Edge Node Session
Establishment"). Its messages are counted in ``pkwbus_mqtt_messages{kind="sparkplug"}``.

It is an output of the lines' streams (:meth:`on_events`: it keeps what changed and
wakes its task; it never awaits there). Raises nothing out of its task: a lost
connection is tried again with back-off.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import random
import ssl
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import aiomqtt

from pkwbus.master.events import Event, HealthChanged, MaintenanceChanged, ValueLanded
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.sparkplug.codec import (
    DataType,
    Metric,
    Payload,
    PropertyValue,
    SparkplugError,
    decode,
    encode,
)
from pkwbus.service.mqtt.sparkplug.commands import CALLER, write_metrics
from pkwbus.service.mqtt.sparkplug.host import BdSeqFile, HostState, state_topic
from pkwbus.service.mqtt.sparkplug.metrics import (
    BD_SEQ,
    BD_SEQ_ALIAS,
    REBIRTH,
    REBIRTH_ALIAS,
    DeviceMetric,
    device_metrics,
    metric_value,
)
from pkwbus.service.runtime import Runtime
from pkwbus.service.writes.path import WritePath

__all__ = ["CALLER", "NAMESPACE", "SparkplugNode"]

log = logging.getLogger("pkwbus.service.mqtt.sparkplug")

NAMESPACE = "spBv1.0"
FIRST_BACKOFF, MAX_BACKOFF = 1.0, 60.0


class SparkplugNode:
    """The edge node ``edge_node_id`` of ``group_id`` (see the module)."""

    def __init__(
        self,
        runtime: Runtime,
        path: WritePath | None,
        *,
        group_id: str,
        edge_node_id: str,
        host: str,
        port: int,
        username: str | None = None,
        password: str | None = None,
        tls: bool = False,
        keepalive: int = 30,
        wall: Callable[[], float] = time.time,
        primary_host_id: str | None = None,
        bd_seq_file: Path | None = None,
        metrics: MqttMetrics | None = None,
    ) -> None:
        self.runtime = runtime
        self.path = path  # None: writes off, DCMD not taken
        self.host, self.port = host, port
        self._account = (username, password)
        self._tls, self._keepalive = tls, keepalive
        self.wall = wall
        base = f"{NAMESPACE}/{group_id}"
        self.node_topics = {k: f"{base}/{k}/{edge_node_id}" for k in ("NBIRTH", "NDEATH", "NCMD")}
        kinds = ("DBIRTH", "DDATA", "DDEATH", "DCMD")
        self.device_base = {k: f"{base}/{k}/{edge_node_id}/" for k in kinds}
        self.bd_seq_file = BdSeqFile(bd_seq_file)
        self.bd_seq = self.bd_seq_file.last()  # the current connection's; the first is 0
        self.state_topic = state_topic(primary_host_id) if primary_host_id else None
        self.host_state = HostState()
        self._counted = metrics.sent["sparkplug"] if metrics is not None else None
        self.client: aiomqtt.Client | None = None
        self.born = asyncio.Event()  # set once the births of a connection are out
        self._seq = 0
        self._send_lock = asyncio.Lock()  # seq in the order of publishing
        self._order = asyncio.Lock()  # births, data and deaths one after the other
        self._metrics: list[DeviceMetric] = []
        self._by_alias: dict[int, DeviceMetric] = {}
        self._types: dict[int, int] = {}
        self._by_reading: dict[Any, DeviceMetric] = {}
        self._sent: dict[int, Any] = {}  # alias -> value last published
        self._changed: dict[str, dict[int, tuple[Any, float]]] = {}
        self._health: dict[str, bool] = {}
        self._alive: set[str] = set()  # drives with a DBIRTH since their last DDEATH
        self._wake = asyncio.Event()
        self._turns: dict[str, asyncio.Lock] = {}
        self._task: asyncio.Task[None] | None = None
        self._stopping = False

    # ------------------------------------------------------------ the stream

    def on_events(self, events: Sequence[Event]) -> None:
        """Keep the values that landed and the drives' health; wake the task."""
        woken = False
        for event in events:
            if isinstance(event, ValueLanded):
                metric = self._by_reading.get(event.key)
                if metric is not None:
                    drive = self._changed.setdefault(metric.drive, {})
                    drive[metric.alias] = (event.reading.value, event.reading.timestamp)
                    woken = True
            elif isinstance(event, HealthChanged):
                self._health[event.drive] = event.up
                woken = True
            elif isinstance(event, MaintenanceChanged):  # out of it: as the drive is now
                state = self.runtime.snapshot.drives.get(event.drive)
                self._health[event.drive] = not event.on and state is not None and state.up
                woken = True
        if woken:
            self._wake.set()

    # ------------------------------------------------------------ running

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run(), name="sparkplug")

    async def stop(self, grace: float = 3.0) -> None:
        """Publish the NDEATH (a clean stop sends no will) and disconnect."""
        self._stopping = True
        client = self.client
        if client is not None:
            with contextlib.suppress(Exception):
                await client.publish(self.node_topics["NDEATH"], self._ndeath(), 1, False,
                                     timeout=grace)  # fmt: skip
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(BaseException):
                await asyncio.wait_for(self._task, grace)

    def rebirth(self) -> None:
        """Publish the births again (a reload changed the drives)."""
        client = self.client
        if client is not None:
            task = asyncio.get_running_loop().create_task(self._births(client))
            task.add_done_callback(_quiet)

    async def _run(self) -> None:
        backoff = FIRST_BACKOFF
        while not self._stopping:
            self.bd_seq = (self.bd_seq + 1) % 256
            self.bd_seq_file.keep(self.bd_seq)
            try:
                async with self._new_client() as client:
                    backoff = FIRST_BACKOFF
                    await self._session(client)
            except (aiomqtt.MqttError, OSError) as exc:
                log.warning("Sparkplug: no connection to %s:%d (%s)", self.host, self.port, exc)
            finally:
                self.client = None
                self.born.clear()
            if self._stopping:
                return
            await asyncio.sleep(backoff * random.uniform(0.8, 1.2))
            backoff = min(backoff * 2, MAX_BACKOFF)

    def _new_client(self) -> aiomqtt.Client:
        return aiomqtt.Client(
            self.host,
            self.port,
            username=self._account[0],
            password=self._account[1],
            protocol=aiomqtt.ProtocolVersion.V5,
            will=aiomqtt.Will(self.node_topics["NDEATH"], self._ndeath(), qos=1, retain=False),
            keepalive=self._keepalive,
            clean_start=True,
            timeout=10.0,
            tls_context=ssl.create_default_context() if self._tls else None,
        )

    async def _session(self, client: aiomqtt.Client) -> None:
        """Births (at once, or once the primary host is online), then commands until the
        connection ends or the primary host goes offline (then the NDEATH)."""
        if self.state_topic is not None:
            self.host_state = HostState()
            await client.subscribe(self.state_topic, qos=1)
        await client.subscribe(self.node_topics["NCMD"], qos=0)
        if self.path is not None:
            await client.subscribe(self.device_base["DCMD"] + "+", qos=0)
        data: asyncio.Task[None] | None = None
        if self.state_topic is None:
            data = await self._born(client)
        try:
            async for message in client.messages:
                if message.topic.value != self.state_topic:
                    self._command(client, message)
                    continue
                payload = message.payload
                online = self.host_state.take(payload if isinstance(payload, bytes) else b"")
                if online and data is None:
                    data = await self._born(client)
                elif online is False and data is not None:
                    log.info("Sparkplug: the primary host is offline; session ended")
                    await client.publish(self.node_topics["NDEATH"], self._ndeath(), 1, False)
                    return
        finally:
            if data is not None:
                data.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await data

    async def _born(self, client: aiomqtt.Client) -> asyncio.Task[None]:
        self.client = client
        await self._births(client)
        return asyncio.get_running_loop().create_task(self._data(client))

    # ------------------------------------------------------------ births and data

    def _ndeath(self) -> bytes:
        bd = Metric(BD_SEQ, timestamp=self._ms(), datatype=DataType.INT64, value=self.bd_seq)
        return encode(Payload(self._ms(), [bd]))

    def _ms(self, at: float | None = None) -> int:
        return round((self.wall() if at is None else at) * 1000)

    async def _births(self, client: aiomqtt.Client) -> None:
        """The NBIRTH and the DBIRTHs, nothing of the node's between them."""
        async with self._order:
            await self._births_now(client)

    async def _births_now(self, client: aiomqtt.Client) -> None:
        self._metrics = device_metrics(self.runtime)
        self._by_alias = {m.alias: m for m in self._metrics}
        self._types = {m.alias: int(m.datatype) for m in self._metrics}
        self._by_reading = {m.reading: m for m in self._metrics if m.reading is not None}
        self._sent.clear()
        self._alive.clear()
        now = self._ms()
        node = [
            Metric(BD_SEQ, BD_SEQ_ALIAS, now, DataType.INT64, self.bd_seq),
            Metric(REBIRTH, REBIRTH_ALIAS, now, DataType.BOOLEAN, False),
        ]
        async with self._send_lock:
            self._seq = 0
            await self._publish(client, self.node_topics["NBIRTH"], Payload(now, node))
        snapshot = self.runtime.snapshot
        for drive in sorted(self.runtime.drives):
            state = snapshot.drives.get(drive)
            up = state is not None and state.up and drive not in snapshot.maintenance
            self._health[drive] = up
            if up:
                await self._dbirth(client, drive)
        self.born.set()

    async def _dbirth(self, client: aiomqtt.Client, drive: str) -> None:
        snapshot, now = self.runtime.snapshot, self._ms()
        metrics = []
        for m in (m for m in self._metrics if m.drive == drive):
            reading = (snapshot.readings.get(m.reading) if m.reading is not None
                       else snapshot.latest.get((drive, m.pnu, m.index or 0)))  # fmt: skip
            value = metric_value(m.datatype, reading.value) if reading is not None else None
            at = self._ms(reading.timestamp) if reading is not None else now
            props = {"engUnit": PropertyValue(DataType.STRING, m.unit)} if m.unit else {}
            metrics.append(Metric(m.name, m.alias, at, m.datatype, value, value is None,
                                  properties=props))  # fmt: skip
            self._sent[m.alias] = value
        self._changed.pop(drive, None)
        await self._send(client, self.device_base["DBIRTH"] + drive, Payload(now, metrics))
        self._alive.add(drive)

    async def _data(self, client: aiomqtt.Client) -> None:
        """DDATA by exception, DDEATH and DBIRTH as drives go and come, until cancelled."""
        while True:
            await self._wake.wait()
            self._wake.clear()
            async with self._order:
                await self._data_now(client)

    async def _data_now(self, client: aiomqtt.Client) -> None:
        for drive, up in list(self._health.items()):
            if drive not in self.runtime.drives:
                continue
            if up and drive not in self._alive:
                await self._dbirth(client, drive)
            elif not up and drive in self._alive:
                self._alive.discard(drive)
                await self._send(client, self.device_base["DDEATH"] + drive,
                                 Payload(self._ms()))  # fmt: skip
        changed, self._changed = self._changed, {}
        for drive, values in changed.items():
            if drive in self._alive:
                await self._ddata(client, drive, values)

    async def _ddata(
        self, client: aiomqtt.Client, drive: str, values: dict[int, tuple[Any, float]]
    ) -> None:
        metrics = []
        for alias, (raw, at) in values.items():
            m = self._by_alias.get(alias)
            if m is None:
                continue
            value = metric_value(m.datatype, raw)
            if alias in self._sent and self._sent[alias] == value:
                continue  # by exception: unchanged
            self._sent[alias] = value
            # No name and no datatype: the birth said them.
            metrics.append(Metric(alias=alias, timestamp=self._ms(at), value=value,
                                  is_null=value is None))  # fmt: skip
        if metrics:
            payload = Payload(self._ms(), metrics)
            await self._send(client, self.device_base["DDATA"] + drive, payload)

    async def _send(self, client: aiomqtt.Client, topic: str, payload: Payload) -> None:
        async with self._send_lock:
            self._seq = (self._seq + 1) % 256
            await self._publish(client, topic, payload)

    async def _publish(self, client: aiomqtt.Client, topic: str, payload: Payload) -> None:
        payload.seq = self._seq
        await client.publish(topic, encode(payload, self._types), qos=0, retain=False)
        if self._counted is not None:
            self._counted.inc()

    # ------------------------------------------------------------ commands

    def _command(self, client: aiomqtt.Client, message: aiomqtt.Message) -> None:
        topic = message.topic.value
        try:
            payload = decode(bytes(message.payload)) if isinstance(message.payload, bytes) else None
        except SparkplugError as exc:
            log.warning("Sparkplug: %s is not a Sparkplug B payload: %s", topic, exc)
            return
        if payload is None:
            return
        if topic == self.node_topics["NCMD"]:
            if any(
                (m.name == REBIRTH or m.alias == REBIRTH_ALIAS) and m.value is True
                for m in payload.metrics
            ):
                self.rebirth()
            return
        drive = topic.removeprefix(self.device_base["DCMD"])
        if self.path is not None and drive != topic and "/" not in drive:
            turn = self._turns.setdefault(drive, asyncio.Lock())
            verified = functools.partial(self._verified, client)
            work = write_metrics(self.path, turn, drive, payload, self._metrics, verified)
            asyncio.get_running_loop().create_task(work).add_done_callback(_quiet)

    async def _verified(self, client: aiomqtt.Client, drive: str, alias: int, value: Any) -> None:
        async with self._order:
            if drive in self._alive:
                await self._ddata(client, drive, {alias: (value, self.wall())})


def _quiet(task: asyncio.Task[Any]) -> None:
    if task.cancelled():
        return
    exc = task.exception()
    if exc is not None and not isinstance(exc, aiomqtt.MqttError):
        log.error("Sparkplug: %r", exc)
