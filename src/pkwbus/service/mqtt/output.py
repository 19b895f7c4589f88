"""The MQTT output: one more member of the lines' outputs list, fed by the same stream
as the collector and the trends, and told of the drives' events by the
history's event stream.

Its observer path only notes what changed (a value landed: its key and reading, latest
wins; a drive's health or maintenance: its name) and wakes a task; the tasks publish:

- values on change beyond the deadband, QoS 0, in slices that leave the loop to the
  lines; and every value again when its heartbeat is due, with its quality then; a value
  that comes while the broker is away is dropped (counted), never stored;
- the drives' statuses, retained QoS 1, on change and on every connection;
- Home Assistant's device configs, retained, on every connection and when Home Assistant
  says ``online``; a drive a reload removed gets an empty retained config (and status);
- the drives' events: stored in the outbox first (its thread), then published QoS 1 in
  their order and deleted once acknowledged; those stored before the connection they go
  out on carry ``"replayed": true``.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import time
from collections.abc import Sequence
from typing import Any

import aiomqtt

from pkwbus.master.events import Event, HealthChanged, MaintenanceChanged, ValueLanded
from pkwbus.master.planning.plan import DescribedAnew, DescribedFromBook
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey
from pkwbus.service.config import Config
from pkwbus.service.config.mqtt import Mqtt
from pkwbus.service.history.store import DriveEvent
from pkwbus.service.history.stream import EventStream
from pkwbus.service.http.views import event_views
from pkwbus.service.mqtt.connection import Connection, NotConnected
from pkwbus.service.mqtt.discovery import OwnConfigs, device_config, discovery_topic
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.outbox import Outbox, OutboxError, Stored, outbox_path
from pkwbus.service.mqtt.values import ValueTopic, ValueTopics, drive_status, quality
from pkwbus.service.runtime import DriveEntry, Runtime

__all__ = ["SLICE", "MqttOutput", "attach"]

log = logging.getLogger("pkwbus.service.mqtt")

SLICE = 500  # messages published before the loop is left to the lines again
BATCH = 100  # events in flight at once (the client's window)
REPLAYED = b',"replayed":true}'


class MqttOutput:
    """The output (see the module) over ``connection``, ``outbox`` kept beside it."""

    def __init__(
        self,
        settings: Mqtt,
        runtime: Runtime,
        connection: Connection,
        outbox: Outbox,
        metrics: MqttMetrics,
    ) -> None:
        self.settings = settings
        self.runtime = runtime
        self.connection = connection
        self.outbox = outbox
        self.metrics = metrics
        self.prefix = settings.prefix
        self.deadband = settings.values.deadband
        self.heartbeat = settings.values.heartbeat
        self.topics = ValueTopics(settings.prefix, lambda: runtime.drives, runtime.snapshot)
        self._pending: dict[ReadingKey, Reading] = {}
        self._statuses: set[str] = set()
        self._described: set[str] = set()  # drives whose withheld polls got a type
        self._wake = asyncio.Event()
        self._incoming: list[tuple[str, bytes]] = []
        self._events = asyncio.Event()
        self._stored = asyncio.Event()
        self._known: dict[str, DriveEntry] = dict(runtime.drives)
        self._gone: list[DriveEntry] = []  # drives removed while the broker was away
        self._tasks: list[asyncio.Task[None]] = []
        self._sent = metrics.sent["value"]
        self._dropped = metrics.drops["value"]
        connection.on_connect(self._session)
        ha = settings.homeassistant
        if ha.discovery:
            connection.subscribe(f"{ha.prefix}/status", self._ha_status, retain_handling=0)
            connection.subscribe(f"{ha.prefix}/device/+/config", self._ha_config, retain_handling=0)
        self._configs = OwnConfigs(ha.prefix, self.prefix)  # found on the broker: stale ones

    # ------------------------------------------------------------ told

    def on_events(self, events: Sequence[Event]) -> None:
        """The lines' stream: only noted here, published by a task."""
        pending, statuses = self._pending, self._statuses
        for event in events:
            kind = type(event)
            if kind is ValueLanded:
                pending[event.key] = event.reading  # type: ignore[union-attr]
            elif kind is HealthChanged or kind is MaintenanceChanged:
                statuses.add(event.drive)  # type: ignore[union-attr]
            elif (kind is DescribedAnew or kind is DescribedFromBook) and any(
                p.described_only
                for p in event.polls  # type: ignore[union-attr]
            ):  # a poll typed by the drive now: its sensor announced
                self._described.add(event.drive)  # type: ignore[union-attr]
        if (pending or statuses or self._described) and not self._wake.is_set():
            self._wake.set()

    def on_drive_events(self, events: list[DriveEvent]) -> None:
        """The history's new events, the oldest first: to the outbox, by a task."""
        for event, view in zip(events, event_views(events), strict=True):
            topic = f"{self.prefix}/{event.line}/{event.drive}/event"
            self._incoming.append((topic, view.model_dump_json().encode()))
        self._events.set()

    def drives_changed(self) -> None:
        """The runtime's drives after a reload: a removed drive's device config and status
        emptied, a changed one's topics made again; each announced again when connected."""
        current = self.runtime.drives
        for name, old in list(self._known.items()):
            entry = current.get(name)
            if entry is old:
                continue
            self.topics.forget(name)
            if entry is None or entry.line != old.line:
                self._clear(old)
        changed = [e for n, e in current.items() if self._known.get(n) is not e]
        self._known = dict(current)
        if changed and self.connection.is_connected:
            self._spawn(self._announce(changed), "mqtt announce")

    # ------------------------------------------------------------ running

    def start(self) -> None:
        self._tasks = [
            self._spawn(self._values(), "mqtt values"),
            self._spawn(self._heartbeats(), "mqtt heartbeat"),
            self._spawn(self._store(), "mqtt outbox"),
        ]
        self.connection.start()

    async def stop(self) -> None:
        """Events still in memory stored, the connection closed (``offline``), the outbox
        closed."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self._incoming:
            with contextlib.suppress(OutboxError):
                batch, self._incoming = self._incoming, []
                await self.outbox.call(lambda: self.outbox.add(batch))
        await self.connection.stop()
        await asyncio.to_thread(self.outbox.close)

    def _spawn(self, work: Any, name: str) -> asyncio.Task[None]:
        task: asyncio.Task[None] = asyncio.get_running_loop().create_task(work, name=name)
        task.add_done_callback(_logged)
        return task

    # ------------------------------------------------------------ values, statuses

    async def _values(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            pending, self._pending = self._pending, {}
            statuses, self._statuses = self._statuses, set()
            described, self._described = self._described, set()
            if statuses and self.connection.is_connected:
                self._publish_statuses(statuses)
            if described and self.connection.is_connected and self.settings.homeassistant.discovery:
                drives = self.runtime.drives
                await self._announce([drives[d] for d in sorted(described) if d in drives])
            await self._publish_values(pending)

    async def _publish_values(self, pending: dict[ReadingKey, Reading]) -> None:
        if not self.connection.is_connected:
            self._dropped.inc(len(pending))
            return
        mono = asyncio.get_running_loop().time()
        get, deadband = self.topics.get, self.deadband
        batch: list[tuple[bytes, bytes]] = []
        topics: list[tuple[ValueTopic, Reading]] = []
        for key, reading in pending.items():
            topic = get(key)
            if topic is None or not topic.changed(reading.value, deadband):
                continue
            batch.append((topic.head, topic.payload(reading, "good")))
            topics.append((topic, reading))
            if len(batch) == SLICE:
                self._hand(batch, topics, mono)
                batch, topics = [], []
                await asyncio.sleep(0)
        self._hand(batch, topics, mono)

    def _hand(
        self,
        batch: list[tuple[bytes, bytes]],
        topics: list[tuple[ValueTopic, Reading]],
        mono: float,
    ) -> int:
        """A slice of values to the socket; how many went."""
        if not batch:
            return 0
        if not self.connection.publish_values(batch):
            self._dropped.inc(len(batch))
            return 0
        for topic, reading in topics:
            topic.last, topic.sent = reading.value, mono
        self._sent.inc(len(batch))
        return len(batch)

    async def _heartbeats(self) -> None:
        """Every value at least every heartbeat: the due ones, checked a few times a
        heartbeat."""
        tick = min(max(self.heartbeat / 10, 0.5), 30.0)
        while True:
            await asyncio.sleep(tick)
            if self.connection.is_connected:
                await self.beat(tick / 2)

    async def beat(self, early: float = 0.0) -> int:
        """Publish each value whose heartbeat is due (within ``early`` seconds), with its
        quality now; how many were published."""
        mono, now = asyncio.get_running_loop().time(), time.time()
        due = mono - self.heartbeat + early
        snapshot, get, sent = self.runtime.snapshot, self.topics.get, 0
        batch: list[tuple[bytes, bytes]] = []
        topics: list[tuple[ValueTopic, Reading]] = []
        for key, reading in list(snapshot.readings.items()):
            topic = get(key)
            if topic is None or topic.sent > due:
                continue
            q = quality(snapshot, key[0], reading, topic.interval, now)
            batch.append((topic.head, topic.payload(reading, q)))
            topics.append((topic, reading))
            if len(batch) == SLICE:
                sent += self._hand(batch, topics, mono)
                batch, topics = [], []
                await asyncio.sleep(0)
        return sent + self._hand(batch, topics, mono)

    def _publish_statuses(self, drives: Sequence[str] | set[str]) -> None:
        snapshot, publish = self.runtime.snapshot, self.connection.publish_nowait
        for name in drives:
            entry = self.runtime.drives.get(name)
            if entry is None:
                continue
            status = drive_status(snapshot, name)
            if publish(self.topics.status_topic(entry), status, 1, True):
                self.metrics.sent["status"].inc()

    def _clear(self, entry: DriveEntry) -> None:
        """A drive gone: its retained status and device config emptied (at the next
        connection when the broker is away)."""
        publish = self.connection.publish_nowait
        done = publish(self.topics.status_topic(entry), b"", 1, True)
        ha = self.settings.homeassistant
        if ha.discovery:
            topic = discovery_topic(ha.prefix, self.prefix, entry.line, entry.name)
            done = publish(topic, b"", 1, True) and done
        if not done:
            self._gone.append(entry)

    async def _announce(self, entries: Sequence[DriveEntry]) -> None:
        """The drives' statuses and Home Assistant device configs, retained."""
        self._publish_statuses([e.name for e in entries])
        ha = self.settings.homeassistant
        if not ha.discovery:
            return
        for n, entry in enumerate(entries, 1):
            payload = device_config(self.prefix, entry, self.topics)
            topic = discovery_topic(ha.prefix, self.prefix, entry.line, entry.name)
            if self.connection.publish_nowait(topic, payload, 1, True):
                self.metrics.sent["discovery"].inc()
            if n % 50 == 0:
                await asyncio.sleep(0)

    def _ha_config(self, message: aiomqtt.Message) -> None:
        """A device config of pkwbus's under this prefix, of none of its drives now: emptied."""
        payload, topic, drives = message.payload, message.topic.value, self.runtime.drives
        if isinstance(payload, bytes | bytearray) and self._configs.stale(drives, topic, payload):
            self.connection.publish_nowait(topic, b"", 1, True)

    def _ha_status(self, message: aiomqtt.Message) -> None:
        if message.payload in (b"online", "online"):
            self._spawn(self._announce(list(self.runtime.drives.values())), "mqtt announce")

    # ------------------------------------------------------------ a connection's session

    async def _session(self) -> None:
        gone, self._gone = self._gone, []
        for entry in gone:
            now = self.runtime.drives.get(entry.name)
            if now is None or now.line != entry.line:  # not back where it was
                self._clear(entry)
        for topic in self.topics.topics.values():  # every value again at the next tick
            if topic is not None:
                topic.sent = float("-inf")
        await self._announce(list(self.runtime.drives.values()))
        await self._drain()

    # ------------------------------------------------------------ events

    async def _store(self) -> None:
        try:  # what an earlier run left in it, shown from the start
            await self.outbox.call(self.outbox.size)
            self._show_outbox(0)
        except OutboxError as exc:
            log.error("MQTT: %s", exc)
        while True:
            await self._events.wait()
            self._events.clear()
            batch, self._incoming = self._incoming, []
            if not batch:
                continue
            try:
                dropped = await self.outbox.call(functools.partial(self.outbox.add, batch))
            except OutboxError as exc:
                log.error("MQTT: %s: %d event(s) not kept", exc, len(batch))
                self.metrics.drops["event"].inc(len(batch))
                continue
            self._show_outbox(dropped)
            self._stored.set()

    async def _drain(self) -> None:
        """The outbox, oldest first, while connected: each deleted once acknowledged."""
        outbox = self.outbox
        while True:
            self._stored.clear()
            rows, dropped = await outbox.call(lambda: outbox.oldest(BATCH))
            self._show_outbox(dropped)
            if not rows:
                await self._stored.wait()
                continue
            since = self.connection.connected_at
            results = await asyncio.gather(
                *(self._send(row, since) for row in rows), return_exceptions=True
            )
            acked = [row.id for row, result in zip(rows, results, strict=True) if result is None]
            await outbox.call(functools.partial(outbox.delete, acked))
            self.metrics.sent["event"].inc(len(acked))
            self._show_outbox(0)
            if len(acked) < len(rows):
                if not self.connection.is_connected:
                    return
                await asyncio.sleep(1.0)  # not acknowledged in time: the same again

    async def _send(self, row: Stored, since: float) -> None:
        payload = row.payload
        if row.stored < since and payload.endswith(b"}"):
            payload = payload[:-1] + REPLAYED
        await self.connection.publish(row.topic, payload, qos=1)

    def _show_outbox(self, dropped: int) -> None:
        if dropped:
            self.metrics.drops["event"].inc(dropped)
            log.warning("MQTT: %d event(s) dropped from the outbox (max_bytes or max_age)",
                        dropped)  # fmt: skip
        self.metrics.outbox_messages.set(self.outbox.messages)
        self.metrics.outbox_bytes.set(self.outbox.bytes)


def _logged(task: asyncio.Task[None]) -> None:
    if task.cancelled():
        return
    exc = task.exception()
    if exc is not None and not isinstance(exc, NotConnected):
        log.error("MQTT: %s stopped: %r", task.get_name(), exc)


def attach(config: Config, runtime: Runtime, stream: EventStream | None) -> MqttOutput | None:
    """The MQTT output of ``config`` (None: no ``mqtt:``), told of the drives' events by
    ``stream``; the assembly makes it one of the outputs' base (kept over reloads: the lines'
    outputs once its load is swapped in), started with the runtime and stopped after
    everything else. :class:`MqttSettingsError` for an account named but unset."""
    settings = config.mqtt
    if settings is None:
        return None
    username, password = settings.credentials()
    metrics = MqttMetrics(runtime.registry)
    connection = Connection(
        settings.host, settings.port, username=username, password=password,
        status_topic=f"{settings.prefix}/status", metrics=metrics, tls=settings.tls,
        keepalive=settings.keepalive,
    )  # fmt: skip
    outbox = Outbox(outbox_path(config.audit_db), settings.outbox.max_bytes,
                    settings.outbox.max_age)  # fmt: skip
    output = MqttOutput(settings, runtime, connection, outbox, metrics)
    if stream is not None:
        stream.listeners.append(output.on_drive_events)
    log.info("MQTT: publishing to %s under %s/", settings.url, settings.prefix)
    return output
