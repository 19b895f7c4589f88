"""A DCMD's metrics written through the one write path (``writable``, limits, the audit
row before the wire, the read-back), the audit row's caller :data:`CALLER`; a drive's
commands one after the other. The verified value goes out at once as DDATA; a refused
one is audited, logged, and nothing is sent."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import Any

from pkwbus.service.mqtt.sparkplug.codec import Metric, Payload
from pkwbus.service.mqtt.sparkplug.metrics import DeviceMetric
from pkwbus.service.writes.checks import ApiError
from pkwbus.service.writes.path import WriteOrder, WritePath

__all__ = ["CALLER", "write_metrics"]

log = logging.getLogger("pkwbus.service.mqtt.sparkplug")

CALLER = "mqtt:sparkplug"  # the audit row's caller of a DCMD's write


Verified = Callable[[str, int, Any], Awaitable[None]]  # drive, alias, value: the DDATA


async def write_metrics(
    path: WritePath,
    turn: asyncio.Lock,
    drive: str,
    payload: Payload,
    metrics: Sequence[DeviceMetric],
    verified: Verified,
) -> None:
    """Write ``payload``'s metrics (of the node's ``metrics``) to ``drive``, holding the
    drive's ``turn``; each verified value to ``verified``."""
    by_alias: Mapping[int, DeviceMetric] = {m.alias: m for m in metrics}
    async with turn:
        for metric in payload.metrics:
            await _write(path, drive, metric, metrics, by_alias, verified)


async def _write(
    path: WritePath,
    drive: str,
    metric: Metric,
    metrics: Sequence[DeviceMetric],
    by_alias: Mapping[int, DeviceMetric],
    verified: Verified,
) -> None:
    found = by_alias.get(metric.alias) if metric.alias is not None else None
    if found is None and metric.name is not None:
        found = next((m for m in metrics if m.drive == drive and m.name == metric.name), None)
    what = found.name if found is not None else metric.name or f"alias {metric.alias}"
    if found is None or found.drive != drive or metric.value is None:
        refusal = ApiError(404, "unknown_parameter", f"{drive} has no metric {what} to write")
        if metric.value is None:
            refusal = ApiError(422, "invalid_value", f"DCMD {what}: no value")
        await path.refuse(drive, what[:32], None, CALLER, refusal)
        log.warning("Sparkplug DCMD refused: %s", refusal)
        return
    value = metric.value
    if isinstance(value, bytes | bool):
        refusal = ApiError(422, "invalid_value", f"{what}: not a number or text")
        await path.refuse(drive, found.parameter, found.index, CALLER, refusal)
        return
    order = WriteOrder(value, found.index, verify=True)
    try:
        done = await path.write(drive, found.parameter, order, CALLER)
    except ApiError as exc:
        log.warning("Sparkplug DCMD %s %s: %s (%s)", drive, what, exc.outcome, exc)
        return
    if done.body.get("verified") is True:
        await verified(drive, found.alias, done.body["value"])
