"""The one connection to the plant's broker (aiomqtt on paho, MQTT 5): kept up with
back-off, the service's status retained on ``{prefix}/status`` (``online`` once connected,
the will ``offline`` when the connection dies, ``offline`` published on a clean stop).

Everything else publishes through it and subscribes through it:

- :meth:`Connection.publish_nowait` hands a QoS 0 message to the client's socket without
  awaiting (False: not connected, nothing sent) - the values' path;
- :meth:`Connection.publish_values` hands many QoS 0 messages to the socket as one write
  (the values' heartbeat and their changes at plant scale);
- :meth:`Connection.publish` awaits the broker's acknowledgement of a QoS 1 message (PUBACK)
  and raises :class:`NotConnected` when there is no connection or it is lost meanwhile;
- :meth:`Connection.subscribe` keeps a topic filter with MQTT 5 subscription options
  (retain handling 2 and no_local by default), subscribed again on every connection; each
  message whose topic matches is handed to its callback, on the event loop (the callback
  must not block: it hands the work to a task or a queue);
- :meth:`Connection.on_connect` runs a coroutine in each connection's session (cancelled
  when the connection is lost), e.g. replaying the outbox.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import ssl
import time
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from typing import Any

import aiomqtt
from paho.mqtt.client import PUBLISH
from paho.mqtt.enums import MQTTErrorCode
from paho.mqtt.properties import Properties
from paho.mqtt.subscribeoptions import SubscribeOptions

from pkwbus.errors import PkwbusError
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.waiting import wait_event

__all__ = ["Connection", "NotConnected", "Subscription", "publish_head"]

log = logging.getLogger("pkwbus.service.mqtt")

FIRST_BACKOFF = 1.0  # seconds before the first reconnect; doubled up to MAX_BACKOFF
MAX_BACKOFF = 60.0
ACK_TIMEOUT = 30.0  # seconds a QoS 1 publish waits for its PUBACK
# Packets waiting for the socket beyond which a message handed without waiting is refused
# (a broker slower than the values): memory stays bounded, the values are dropped, counted.
MAX_WAITING = 20_000
# The paho client's queue of packets for its socket writer (not public API). The values'
# path hands it whole slices; paho's public publish per value costs 75 times the CPU, and
# aiomqtt's awaited publish 250 times (bench/mqtt_fast_path.py, 10,080 values: 0.35 us,
# 26 us and 87 us a value; docs/benchmarks.md, "MQTT: the values' fast path"). A paho
# without it: the public publish per value, the values still go.
PACKET_QUEUE = "_packet_queue"


class NotConnected(PkwbusError):
    """The broker is not connected (or the connection was lost before it acknowledged)."""


@dataclass
class Subscription:
    """A topic filter kept over reconnects, its MQTT 5 options and its callback."""

    topic: str
    callback: Callable[[aiomqtt.Message], None]
    options: SubscribeOptions


class Connection:
    """The service's broker connection (see the module). ``status_topic``: the service's
    retained status, ``online``/``offline``."""

    def __init__(
        self,
        host: str,
        port: int,
        *,
        username: str | None,
        password: str | None,
        status_topic: str,
        metrics: MqttMetrics,
        tls: bool = False,
        keepalive: int = 30,
        identifier: str | None = None,
    ) -> None:
        self.host, self.port = host, port
        self._username, self._password = username, password
        self.status_topic = status_topic
        self.metrics = metrics
        self._tls = tls
        self._keepalive = keepalive
        self.identifier = identifier or f"pkwbus-{random.getrandbits(48):012x}"
        self._client: aiomqtt.Client | None = None
        self.connected = asyncio.Event()
        self.connected_at = 0.0  # wall clock of the current connection's start (0: none)
        self._subscriptions: list[Subscription] = []
        self._sessions: list[Callable[[], Coroutine[Any, Any, None]]] = []
        self._task: asyncio.Task[None] | None = None
        self._stopping = asyncio.Event()
        self._said_down = False

    # ------------------------------------------------------------ the API

    @property
    def is_connected(self) -> bool:
        return self._client is not None

    def publish_nowait(
        self,
        topic: str,
        payload: bytes | str,
        qos: int = 0,
        retain: bool = False,
        properties: Properties | None = None,
    ) -> bool:
        """Hand a message to the client's socket at once (no acknowledgement awaited);
        False when not connected or the client refused it (nothing was sent)."""
        client = self._client
        if client is None:
            return False
        # The paho client under aiomqtt: its publish queues the packet for the socket's
        # writer on the event loop and returns at once.
        info = client._client.publish(topic, payload, qos, retain, properties)
        return info.rc == MQTTErrorCode.MQTT_ERR_SUCCESS

    def publish_values(self, messages: Sequence[tuple[bytes, bytes]]) -> bool:
        """Hand QoS 0 messages, not retained, to the socket as one write: each ``(head,
        payload)`` with ``head`` from :func:`publish_head`. False when not connected, or
        when the socket is that far behind (nothing was sent)."""
        client = self._client
        if client is None:
            return False
        paho = client._client
        if paho._sock is None or len(paho._out_packet) > MAX_WAITING:
            return False
        queue = getattr(paho, PACKET_QUEUE, None)
        if queue is None:  # the public publish (see PACKET_QUEUE)
            for head, payload in messages:
                size = int.from_bytes(head[:2], "big")
                paho.publish(head[2 : 2 + size].decode(), payload, 0, False)
            return True
        data = bytearray()
        for head, payload in messages:
            data += _fixed_header(len(head) + len(payload))
            data += head
            data += payload
        # One entry of the paho client's queue of packets for the socket's writer: the
        # PUBLISH packets of MQTT 5 (OASIS, MQTT Version 5.0, 3.3) one after the other. The
        # entry is marked QoS 1 so that paho looks for no QoS 0 message of its own in it
        # (those have a message info to set); nothing awaits an acknowledgement.
        queue(PUBLISH, bytes(data), 0, 1)
        return True

    async def publish(
        self,
        topic: str,
        payload: bytes | str,
        qos: int = 1,
        retain: bool = False,
        properties: Properties | None = None,
        *,
        timeout: float = ACK_TIMEOUT,
    ) -> None:
        """Publish and wait for the broker's acknowledgement (QoS 1: PUBACK);
        :class:`NotConnected` when there is no connection or it failed meanwhile."""
        client = self._client
        if client is None:
            raise NotConnected("the MQTT broker is not connected")
        try:
            await client.publish(topic, payload, qos, retain, properties, timeout=timeout)
        except aiomqtt.MqttError as exc:
            raise NotConnected(f"the MQTT broker did not take the message: {exc}") from None

    def subscribe(
        self,
        topic: str,
        callback: Callable[[aiomqtt.Message], None],
        *,
        qos: int = 1,
        no_local: bool = True,
        retain_as_published: bool = True,
        retain_handling: int = SubscribeOptions.RETAIN_DO_NOT_SEND,
    ) -> Subscription:
        """Keep ``topic`` (a filter) subscribed on every connection, with MQTT 5 options;
        each matching message goes to ``callback`` on the event loop. Subscribed at once
        when connected (in a task)."""
        options = SubscribeOptions(
            qos=qos,
            noLocal=no_local,
            retainAsPublished=retain_as_published,
            retainHandling=retain_handling,
        )
        found = Subscription(topic, callback, options)
        self._subscriptions.append(found)
        client = self._client
        if client is not None:
            task = asyncio.get_running_loop().create_task(
                self._subscribe(client, found), name=f"mqtt subscribe {topic}"
            )
            task.add_done_callback(_quiet)
        return found

    def unsubscribe(self, subscription: Subscription) -> None:
        """Stop handing ``subscription``'s messages (unsubscribed at the next connection)."""
        with contextlib.suppress(ValueError):
            self._subscriptions.remove(subscription)

    def on_connect(self, session: Callable[[], Coroutine[Any, Any, None]]) -> None:
        """Run ``session()`` in every connection (cancelled when it is lost)."""
        self._sessions.append(session)

    # ------------------------------------------------------------ running

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run(), name="mqtt")

    async def stop(self, grace: float = 3.0) -> None:
        """Say ``offline`` (retained) and disconnect."""
        self._stopping.set()
        client = self._client
        if client is not None:
            with contextlib.suppress(Exception):
                await client.publish(self.status_topic, "offline", 1, True, timeout=grace)
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(BaseException):
                await asyncio.wait_for(self._task, grace)

    def _new_client(self) -> aiomqtt.Client:
        context = ssl.create_default_context() if self._tls else None
        return aiomqtt.Client(
            self.host,
            self.port,
            username=self._username,
            password=self._password,
            identifier=self.identifier,
            protocol=aiomqtt.ProtocolVersion.V5,
            will=aiomqtt.Will(self.status_topic, "offline", qos=1, retain=True),
            keepalive=self._keepalive,
            clean_start=True,
            timeout=10.0,
            max_inflight_messages=100,
            tls_context=context,
            logger=logging.getLogger("pkwbus.service.mqtt.client"),
        )

    async def _run(self) -> None:
        backoff = FIRST_BACKOFF
        first = True
        while not self._stopping.is_set():
            if not first:
                self.metrics.reconnects.inc()
            first = False
            client = self._new_client()
            try:
                async with client:
                    backoff = FIRST_BACKOFF
                    await self._session(client)
            except aiomqtt.MqttError as exc:
                self._down(str(exc))
            except OSError as exc:
                self._down(exc.strerror or str(exc))
            finally:
                self._lost()
            if self._stopping.is_set():
                break
            # Back-off with a little jitter, so a plant's services do not come back at once.
            delay = backoff * random.uniform(0.8, 1.2)
            backoff = min(backoff * 2, MAX_BACKOFF)
            await wait_event(self._stopping, delay)

    async def _session(self, client: aiomqtt.Client) -> None:
        await client.publish(self.status_topic, "online", 1, True)
        self.metrics.sent["status"].inc()
        for subscription in list(self._subscriptions):
            await self._subscribe(client, subscription)
        self._client = client
        self.connected_at = time.time()
        self.connected.set()
        self.metrics.connected.set(1)
        if self._said_down:
            log.info("MQTT: connected again to %s:%d", self.host, self.port)
        else:
            log.info("MQTT: connected to %s:%d", self.host, self.port)
        self._said_down = False
        tasks: list[asyncio.Task[None]] = [
            asyncio.get_running_loop().create_task(session(), name="mqtt session")
            for session in self._sessions
        ]
        for task in tasks:
            task.add_done_callback(_quiet)
        try:
            async for message in client.messages:
                self._dispatch(message)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    async def _subscribe(self, client: aiomqtt.Client, subscription: Subscription) -> None:
        await client.subscribe(subscription.topic, options=subscription.options)

    def _dispatch(self, message: aiomqtt.Message) -> None:
        for subscription in self._subscriptions:
            if message.topic.matches(subscription.topic):
                try:
                    subscription.callback(message)
                except Exception:  # one callback's defect must not end the connection
                    log.exception("MQTT: the handler of %s failed", subscription.topic)

    def _lost(self) -> None:
        self._client = None
        self.connected.clear()
        self.connected_at = 0.0
        self.metrics.connected.set(0)

    def _down(self, why: str) -> None:
        if not self._said_down and not self._stopping.is_set():
            log.warning("MQTT: no connection to %s:%d (%s): trying again", self.host,
                        self.port, why)  # fmt: skip
        self._said_down = True


def publish_head(topic: str) -> bytes:
    """The part of an MQTT 5 PUBLISH packet after its fixed header and before its
    payload, for QoS 0: the topic's length and bytes, and no properties."""
    name = topic.encode()
    return len(name).to_bytes(2, "big") + name + b"\x00"


def _fixed_header(remaining: int) -> bytes:
    """A PUBLISH's fixed header, QoS 0, not retained: the type, and the remaining length
    as MQTT's variable byte integer."""
    out = bytearray(b"\x30")
    while True:
        byte, remaining = remaining & 0x7F, remaining >> 7
        out.append(byte | 0x80 if remaining else byte)
        if not remaining:
            return bytes(out)


def _quiet(task: asyncio.Task[object]) -> None:
    """A session's task ended: its failure logged, never left unretrieved."""
    if task.cancelled():
        return
    exc = task.exception()
    if exc is not None and not isinstance(exc, NotConnected | aiomqtt.MqttError):
        log.error("MQTT: %s failed: %r", task.get_name(), exc)
