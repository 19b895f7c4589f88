"""The MQTT output's own series: the connection, the messages by kind, the outbox and
what was dropped (README, "Metrics")."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge

__all__ = ["KINDS", "MqttMetrics"]

# What the output publishes: values, drive and service statuses, drive events, Home
# Assistant discovery configs, what others publish through the connection (M2's
# results; "other"), and the Sparkplug B edge node's messages (its own connection).
KINDS = ("value", "status", "event", "discovery", "other", "sparkplug")


class MqttMetrics:
    """``pkwbus_mqtt_*``: registered in ``registry`` once, at the output's construction."""

    def __init__(self, registry: CollectorRegistry) -> None:
        self.connected = Gauge(
            "pkwbus_mqtt_connected", "1 while pkwbus is connected to the MQTT broker",
            registry=registry,
        )  # fmt: skip
        self.messages = Counter(
            "pkwbus_mqtt_messages",
            "Messages handed to the broker, by kind (value, status, event, discovery, other,"
            " sparkplug);"
            " an event once the broker acknowledged it",
            ["kind"],
            registry=registry,
        )
        self.outbox_messages = Gauge(
            "pkwbus_mqtt_outbox_messages",
            "Drive events kept in the outbox until the broker acknowledges them",
            registry=registry,
        )
        self.outbox_bytes = Gauge(
            "pkwbus_mqtt_outbox_bytes", "The payload bytes the outbox keeps", registry=registry
        )
        self.dropped = Counter(
            "pkwbus_mqtt_dropped",
            "Messages never sent, by kind: a value while the broker was away (values are not"
            " kept), an event pushed out of the outbox by max_bytes or max_age",
            ["kind"],
            registry=registry,
        )
        self.reconnects = Counter(
            "pkwbus_mqtt_reconnects",
            "Connections to the broker tried again after one failed or was lost",
            registry=registry,
        )
        # Each kind's child, made once: the hot path counts without a label lookup.
        self.sent = {kind: self.messages.labels(kind) for kind in KINDS}
        self.drops = {kind: self.dropped.labels(kind) for kind in KINDS}
