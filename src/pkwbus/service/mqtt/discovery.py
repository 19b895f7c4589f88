"""Home Assistant's MQTT device discovery: one retained config per drive,
``{ha prefix}/device/pkwbus_{line}_{drive}/config``, with a sensor per polled value.

Each sensor has the value's name and unit; its ``device_class`` where Home Assistant has
one for that unit (frequency, current, voltage, power, energy, temperature, duration,
pressure, apparent and reactive power), and its ``state_class``: ``total_increasing`` for
a counter the drive keeps of its own life (energy, running hours, power-ups: the catalog's
``counter``), ``measurement`` for any other number, none for a value with named options.
The device is available while both the service's status and the drive's status say
``online`` (a drive in maintenance is unavailable). An empty retained payload removes
the device (a reload removed the drive).
"""

from __future__ import annotations

import json
import re
from typing import Any, Final

from pkwbus import __version__
from pkwbus.protocol.values.types import ValueType
from pkwbus.service.mqtt.values import ValueTopics
from pkwbus.service.runtime import DriveEntry

__all__ = ["DEVICE_CLASSES", "device_config", "device_id", "discovery_topic"]

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


def device_id(line: str, drive: str) -> str:
    """``pkwbus_{line}_{drive}``, with what Home Assistant does not take in an id as _."""
    return _ID.sub("_", f"pkwbus_{line}_{drive}")


def discovery_topic(ha_prefix: str, line: str, drive: str) -> str:
    return f"{ha_prefix}/device/{device_id(line, drive)}/config"


def device_config(prefix: str, entry: DriveEntry, topics: ValueTopics) -> bytes:
    """The drive's device discovery payload (JSON, keys sorted)."""
    ident = device_id(entry.line, entry.name)
    components: dict[str, dict[str, Any]] = {}
    for poll in entry.polls:
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
