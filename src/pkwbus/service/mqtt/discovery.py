"""Home Assistant's MQTT device discovery: one retained config per drive,
``{ha prefix}/device/{id}/config`` (``id``: ``pkwbus_{line}_{drive}`` under the default
prefix, :func:`~pkwbus.service.config.mqtt.ha_device_id`), with a sensor per polled value.

Each sensor has the value's name and unit; its ``device_class`` where Home Assistant has
one for that unit (frequency, current, voltage, power, energy, temperature, duration,
pressure, apparent and reactive power), and its ``state_class``: ``total_increasing`` for
a counter the drive keeps of its own life (energy, running hours, power-ups: the catalog's
``counter``), ``measurement`` for any other number, none for a value with named options.
The device is available while both the service's status and the drive's status say
``online`` (a drive in maintenance is unavailable). A poll that waits for the drive to
describe its type (no vendor document types it) has no sensor until the drive has. An
empty retained payload removes the device (a reload removed the drive). A retained
config of pkwbus's under the same prefix (its availability names ``{prefix}/status``)
for a device that is not one of the service's drives now, a drive removed while it was
stopped or the id of an earlier version, is emptied when found (:func:`stale_config`).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from typing import Any, Final

from pkwbus import __version__
from pkwbus.protocol.values.types import ValueType
from pkwbus.service.config.mqtt import ha_device_id
from pkwbus.service.mqtt.values import ValueTopics
from pkwbus.service.runtime import DriveEntry

__all__ = [
    "DEVICE_CLASSES", "OwnConfigs", "device_config", "device_id", "discovery_topic", "stale_config",
]  # fmt: skip

# Home Assistant's sensor device classes by the units it accepts for them.
DEVICE_CLASSES: Final = {
    **dict.fromkeys(("Hz", "kHz", "MHz"), "frequency"),
    **dict.fromkeys(("A", "mA"), "current"),
    **dict.fromkeys(("V", "mV", "kV"), "voltage"),
    **dict.fromkeys(("W", "kW", "MW"), "power"),
    **dict.fromkeys(("Wh", "kWh", "MWh", "J", "kJ", "MJ", "GJ"), "energy"),
    **dict.fromkeys(("°C", "°F", "K"), "temperature"),
    **dict.fromkeys(("ms", "s", "min", "h", "d"), "duration"),
    **dict.fromkeys(("Pa", "hPa", "kPa", "bar", "mbar", "psi"), "pressure"),
    **dict.fromkeys(("VA", "kVA"), "apparent_power"),
    **dict.fromkeys(("var", "kvar"), "reactive_power"),
}
_ID = re.compile(r"[^A-Za-z0-9_-]")
# The drive's status as availability: maintenance is not available either.
_AVAILABLE = "{{ 'online' if value == 'online' else 'offline' }}"


device_id = ha_device_id


def discovery_topic(ha_prefix: str, prefix: str, line: str, drive: str) -> str:
    return f"{ha_prefix}/device/{device_id(prefix, line, drive)}/config"


def stale_config(prefix: str, payload: bytes) -> bool:
    """Whether ``payload``, a retained device config, is one pkwbus published under
    ``prefix`` (its first availability topic ``{prefix}/status``); asked only of a topic
    that is not one of the drives' now (:class:`OwnConfigs`)."""
    try:
        doc = json.loads(payload) if payload else None
    except ValueError:  # not JSON (UnicodeDecodeError is one): not pkwbus's
        return False
    if not isinstance(doc, dict) or not isinstance(doc.get("origin"), dict):
        return False
    available = doc.get("availability")
    first = available[0] if isinstance(available, list) and available else None
    return (
        doc["origin"].get("name") == "pkwbus"
        and isinstance(first, dict)
        and first.get("topic") == f"{prefix}/status"
    )


class OwnConfigs:
    """The device config topics of the service's drives now, made again only when the
    runtime's drives are another mapping (a load swapped in): a retained config found on the
    broker costs one set lookup when it is a drive's own, its JSON read only otherwise."""

    def __init__(self, ha_prefix: str, prefix: str) -> None:
        self.ha_prefix, self.prefix = ha_prefix, prefix
        self._of: Mapping[str, DriveEntry] | None = None
        self._topics: frozenset[str] = frozenset()

    def stale(self, drives: Mapping[str, DriveEntry], topic: str, payload: bytes) -> bool:
        """Whether the config ``payload`` on ``topic`` is pkwbus's under the prefix for none
        of ``drives`` (:func:`stale_config`)."""
        if drives is not self._of:
            self._of = drives
            self._topics = frozenset(
                discovery_topic(self.ha_prefix, self.prefix, e.line, e.name)
                for e in drives.values()
            )
        return topic not in self._topics and stale_config(self.prefix, payload)


def device_config(prefix: str, entry: DriveEntry, topics: ValueTopics) -> bytes:
    """The drive's device discovery payload (JSON, keys sorted)."""
    ident = device_id(prefix, entry.line, entry.name)
    components: dict[str, dict[str, Any]] = {}
    decoding = topics.snapshot.decoding.get(entry.name)
    described = decoding.described if decoding is not None else {}
    for poll in entry.polls:
        told = described.get(poll.request.pnu)
        if poll.described_only and (told is None or told.vtype is None):
            continue  # not polled until the drive describes its type (then announced again)
        topic = topics.get((entry.name, poll.parameter, poll.index))
        if topic is None:
            continue
        fmt = poll.fmt
        key = _ID.sub("_", f"{poll.parameter}_{poll.index}")
        name = fmt.name or poll.parameter
        if topic.topic.endswith(f"/{poll.index}") and fmt.array is not None:
            name = f"{name} [{poll.index}]"
        sensor: dict[str, Any] = {
            "platform": "sensor",
            "name": name,
            "unique_id": f"{ident}_{key}",
            "state_topic": topic.topic,
            "value_template": "{{ value_json.v }}",
        }
        if fmt.unit:
            sensor["unit_of_measurement"] = fmt.unit
            device_class = DEVICE_CLASSES.get(fmt.unit)
            if device_class is not None:
                sensor["device_class"] = device_class
        if fmt.counter:
            sensor["state_class"] = "total_increasing"
        elif not fmt.options and fmt.vtype is not ValueType.TEXT:
            sensor["state_class"] = "measurement"
        components[key] = sensor
    payload = {
        "device": {
            "identifiers": [ident],
            "name": entry.name,
            "model": f"{entry.target.protocol.value} drive, address {entry.target.address}",
            "suggested_area": entry.line,
        },
        "origin": {"name": "pkwbus", "sw_version": __version__},
        "components": components,
        "availability": [
            {"topic": f"{prefix}/status"},
            {"topic": topics.status_topic(entry), "value_template": _AVAILABLE},
        ],
        "availability_mode": "all",
        "qos": 0,
    }
    return json.dumps(payload, sort_keys=True, ensure_ascii=False).encode()
