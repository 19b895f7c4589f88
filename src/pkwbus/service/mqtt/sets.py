"""The set topics on the service's broker connection
(:class:`~pkwbus.service.mqtt.connection.Connection`, aiomqtt on paho, MQTT 5): how they
are subscribed, how a delivered message becomes a
:class:`~pkwbus.service.mqtt.writes.SetMessage`, how a
:class:`~pkwbus.service.mqtt.writes.Reply` is published.

The subscription: QoS 1, no local, retain-as-published (a set published retained keeps
its flag, and is refused), retain handling 2 (a stored retained set is never
delivered), kept over reconnects by the connection. A reply to a response topic carries
the request's correlation data. Raises nothing: a reply the broker does not take is
logged by :class:`~pkwbus.service.mqtt.writes.SetTopics` (the audit row holds the
outcome).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import aiomqtt
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from paho.mqtt.subscribeoptions import SubscribeOptions

from pkwbus.service.mqtt.connection import Connection
from pkwbus.service.mqtt.writes import Reply, SetMessage, SetTopics
from pkwbus.service.writes.path import WritePath

__all__ = ["replies_through", "set_message", "take_sets"]


def take_sets(connection: Connection, path: WritePath, prefix: str) -> SetTopics:
    """The set topics of ``prefix`` written through ``path``, subscribed on ``connection``
    (``mqtt.writes: allow_list``), their results published through it."""
    sets = SetTopics(path, prefix, replies_through(connection))
    connection.subscribe(
        sets.topic_filter,
        lambda message: sets.take(set_message(message, sets.clock())),
        qos=1,
        no_local=True,
        retain_as_published=True,
        retain_handling=SubscribeOptions.RETAIN_DO_NOT_SEND,
    )
    return sets


def set_message(message: aiomqtt.Message, received: float) -> SetMessage:
    """A delivered message as the set topics take it, ``received`` on their clock."""
    props: Any = message.properties
    response = getattr(props, "ResponseTopic", None)
    correlation = getattr(props, "CorrelationData", None)
    expiry = getattr(props, "MessageExpiryInterval", None)
    payload = message.payload
    if isinstance(payload, str):
        payload = payload.encode()
    elif not isinstance(payload, bytes | bytearray):
        payload = b"" if payload is None else str(payload).encode()
    return SetMessage(
        topic=message.topic.value,
        payload=bytes(payload),
        retain=bool(message.retain),
        response_topic=response if isinstance(response, str) and response else None,
        correlation_data=bytes(correlation) if correlation is not None else None,
        expiry=float(expiry) if isinstance(expiry, int) else None,
        received=received,
    )


def replies_through(connection: Connection) -> Callable[[Reply], Awaitable[None]]:
    """The set topics' way to publish through ``connection`` (never retained; a result
    waits for the broker's acknowledgement), counted as ``other`` messages."""

    async def publish(reply: Reply) -> None:
        properties = None
        if reply.correlation_data is not None:
            properties = Properties(PacketTypes.PUBLISH)  # type: ignore[no-untyped-call]
            properties.CorrelationData = reply.correlation_data
        await connection.publish(reply.topic, reply.payload, reply.qos, False, properties)
        connection.metrics.sent["other"].inc()

    return publish
