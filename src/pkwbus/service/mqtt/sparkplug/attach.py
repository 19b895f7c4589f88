"""The Sparkplug node as one of the service's outputs (``mqtt.sparkplug``)."""

from __future__ import annotations

import logging
from pathlib import Path

from pkwbus.service.config.mqtt import Mqtt
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.sparkplug.node import SparkplugNode
from pkwbus.service.runtime import Runtime
from pkwbus.service.writes.path import WritePath

__all__ = ["attach_sparkplug"]

log = logging.getLogger("pkwbus.service.mqtt.sparkplug")


def attach_sparkplug(
    settings: Mqtt | None,
    runtime: Runtime,
    path: WritePath,
    *,
    metrics: MqttMetrics | None = None,
    bd_seq_file: Path | None = None,
) -> SparkplugNode | None:
    """The Sparkplug node of ``settings`` (None without ``mqtt.sparkplug``), one of the
    lines' outputs once the assembly made it one of the outputs' base and swapped its load in
    (kept over reloads, started with the runtime and stopped after everything else); DCMD taken only
    with ``mqtt.writes: allow_list``; its messages counted in ``metrics``, its ``bdSeq``
    kept in ``bd_seq_file``.
    :class:`~pkwbus.service.config.mqtt.MqttSettingsError` for an account named but unset."""
    if settings is None or settings.sparkplug is None:
        return None
    username, password = settings.credentials()
    node = SparkplugNode(
        runtime,
        path if settings.writes == "allow_list" else None,
        group_id=settings.sparkplug.group_id,
        edge_node_id=settings.sparkplug.edge_node_id,
        host=settings.host,
        port=settings.port,
        username=username,
        password=password,
        tls=settings.tls,
        keepalive=settings.keepalive,
        primary_host_id=settings.sparkplug.primary_host_id,
        bd_seq_file=bd_seq_file,
        metrics=metrics,
    )
    log.info("Sparkplug B: edge node %s of group %s", settings.sparkplug.edge_node_id,
             settings.sparkplug.group_id)  # fmt: skip
    return node
