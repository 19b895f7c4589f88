"""The ``mqtt:`` section: the plant's broker, what pkwbus publishes there and how long it
keeps what the broker did not take (README, "MQTT").

The broker account comes from the environment (``username_env``, ``password_env``),
read when the service starts (:meth:`Mqtt.credentials`); a name given whose variable
is unset is a :class:`MqttSettingsError` then, never an anonymous connection. The
section needs the ``mqtt`` extra (aiomqtt): without it the file is refused, naming
``pip install pkwbus[mqtt]``.
"""

from __future__ import annotations

import importlib.util
import os
import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import Annotated, Final, Self
from urllib.parse import urlsplit

from pydantic import Field, PlainValidator, model_validator

from pkwbus.errors import PkwbusError
from pkwbus.notation import durations
from pkwbus.notation.durations import parse_duration
from pkwbus.notation.hostport import MAX_TCP_PORT, check_host
from pkwbus.notation.limits import parse_size
from pkwbus.notation.problems import short
from pkwbus.service.config.base import Model, Place

__all__ = [
    "DEFAULT_PORTS",
    "EXTRA_HINT",
    "MAX_OUTBOX_BYTES",
    "HomeAssistant",
    "Mqtt",
    "MqttSettingsError",
    "Outbox",
    "Sparkplug",
    "Values",
    "ha_device_id",
    "ha_id_clashes",
    "mqtt_report",
]

DEFAULT_PORTS: Final = {"mqtt": 1883, "mqtts": 8883}
MAX_OUTBOX_BYTES: Final = 64 * 1024**3  # 64 GiB: the outbox is a file on the audit's disk
EXTRA_HINT: Final = "MQTT needs the mqtt extra: pip install pkwbus[mqtt]"
_ENV_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,127}$")
# A topic level of ours: no wildcard, no empty level, nothing MQTT forbids in a name.
_LEVEL = re.compile(r"^[^/+#\x00]+$")


class MqttSettingsError(PkwbusError):
    """The MQTT section cannot be used as the environment stands (an account named but
    unset)."""


def _env_name(value: object) -> str:
    if not isinstance(value, str) or not _ENV_NAME.match(value):
        raise ValueError(
            f"{short(value)} is not an environment variable name (letters, digits and _)"
        )
    return value


def _prefix(value: object) -> str:
    """A topic prefix of one or more levels (``pkwbus``, ``pkwbus/hall-a``)."""
    if not isinstance(value, str) or not value or len(value) > 200:
        raise ValueError("must be a topic prefix such as pkwbus or pkwbus/hall-a")
    levels = value.split("/")
    if value.startswith("$") or not all(_LEVEL.match(level) for level in levels):
        raise ValueError(
            f"{short(value)} is not a topic prefix: levels without +, #, empty levels or a"
            " leading $ (pkwbus or pkwbus/hall-a)"
        )
    return value


def _url(value: object) -> str:
    """``mqtt://HOST[:PORT]`` or ``mqtts://HOST[:PORT]`` (TLS)."""
    hint = "write mqtt://HOST:PORT, or mqtts://HOST:PORT for TLS"
    if not isinstance(value, str):
        raise ValueError(f"{short(value)} is not a broker address: {hint}")
    parts = urlsplit(value)
    if parts.scheme not in DEFAULT_PORTS or not parts.hostname:
        raise ValueError(f"{short(value)} is not a broker address: {hint}")
    if parts.username or parts.password:
        raise ValueError("the account is not written in the url: name it with username_env")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise ValueError(f"{short(value)}: a broker address has no path or query; {hint}")
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"{short(value)}: the port is not 1-{MAX_TCP_PORT}") from None
    if port == 0:
        raise ValueError(f"{short(value)}: the port is not 1-{MAX_TCP_PORT}")
    check_host(parts.hostname)
    return value


def _writes(value: object) -> str:
    """``off`` (YAML reads a bare off as false) or ``allow_list``."""
    if value is False or value == "off":
        return "off"
    if value == "allow_list":
        return "allow_list"
    raise ValueError(f"must be off or allow_list, not {short(repr(value))}")


def _deadband(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 <= value < 1e15:
        raise ValueError(f"{short(value)} is not a deadband: a number 0 or more, in the unit")
    return float(value)


class Values(Model):
    """Values are published on change beyond ``deadband`` (in the value's unit) and at
    least every ``heartbeat`` seconds."""

    deadband: Annotated[float, PlainValidator(_deadband)] = 0.0
    heartbeat: Annotated[
        float, PlainValidator(lambda v: parse_duration(v, durations.MQTT_HEARTBEAT))
    ] = 300.0


_HA_ID = re.compile(r"[^A-Za-z0-9_-]")


def ha_device_id(prefix: str, line: str, drive: str) -> str:
    """A drive's Home Assistant device id: ``{prefix}_{line}_{drive}`` with what Home
    Assistant does not take in an id as _ (``pkwbus_{line}_{drive}`` under the default
    prefix); the site a prefix carries (``pkwbus/hall-a``) keeps apart the drives of two
    services on one broker that have the same line and drive names."""
    return _HA_ID.sub("_", f"{prefix}_{line}_{drive}")


def ha_id_clashes(mqtt: Mqtt | None, drives: Iterable[tuple[str, str, str]]) -> list[Place]:
    """Drives (place, line, name) whose Home Assistant device ids would be one (``fan.1`` and
    ``fan_1`` on a line): one device would hide the other. None while discovery is off."""
    if mqtt is None or not mqtt.homeassistant.discovery:
        return []
    seen: dict[str, tuple[str, str]] = {}
    problems: list[Place] = []
    for place, line, name in drives:
        ident = ha_device_id(mqtt.prefix, line, name)
        first, other = seen.setdefault(ident, (place, name))
        if first != place:
            problems.append((f"{place}.name", f"{name!r} has the Home Assistant device id {ident}"
                             f" of {other!r} ({first}): an id keeps only A-Z, a-z, 0-9, _ and"
                             " -; rename one"))  # fmt: skip
    return problems


class HomeAssistant(Model):
    """Home Assistant's MQTT device discovery: one retained config per drive."""

    discovery: bool = True
    prefix: Annotated[str, PlainValidator(_prefix)] = "homeassistant"


class Outbox(Model):
    """What is kept on disk of the QoS 1 messages while the broker is away."""

    max_bytes: Annotated[int, PlainValidator(lambda v: parse_size(v, 4096, MAX_OUTBOX_BYTES))] = (
        64 * 1024**2
    )
    max_age: Annotated[
        float, PlainValidator(lambda v: parse_duration(v, durations.MQTT_OUTBOX_AGE))
    ] = 24 * 3600.0


def _host_id(value: object) -> str:
    """A primary host application's id: one topic level (``scada``)."""
    if not isinstance(value, str) or len(value) > 200 or not _LEVEL.match(value):
        raise ValueError(
            f"{short(value)} is not a host id: one topic level without /, +, # (scada)"
        )
    return value


class Sparkplug(Model):
    """Sparkplug B (an option): the edge node's group and name, and the primary host
    application whose STATE it waits for (None: born at once)."""

    group_id: Annotated[str, PlainValidator(_prefix)]
    edge_node_id: Annotated[str, PlainValidator(_prefix)]
    primary_host_id: Annotated[str, PlainValidator(_host_id)] | None = None


class Mqtt(Model):
    """The ``mqtt:`` section (absent: no MQTT)."""

    url: Annotated[str, PlainValidator(_url)]
    username_env: Annotated[str, PlainValidator(_env_name)] | None = None
    password_env: Annotated[str, PlainValidator(_env_name)] | None = None
    prefix: Annotated[str, PlainValidator(_prefix)] = "pkwbus"
    values: Values = Values()
    homeassistant: HomeAssistant = HomeAssistant()
    writes: Annotated[str, PlainValidator(_writes)] = "off"
    outbox: Outbox = Outbox()
    sparkplug: Sparkplug | None = None
    # Seconds between the pings that keep the connection and tell a dead one.
    keepalive: int = Field(default=30, ge=5, le=3600)

    @model_validator(mode="after")
    def _the_extra(self) -> Self:
        if importlib.util.find_spec("aiomqtt") is None:
            raise ValueError(EXTRA_HINT)
        return self

    @property
    def tls(self) -> bool:
        return urlsplit(self.url).scheme == "mqtts"

    @property
    def host(self) -> str:
        return urlsplit(self.url).hostname or ""

    @property
    def port(self) -> int:
        parts = urlsplit(self.url)
        return parts.port or DEFAULT_PORTS[parts.scheme]

    def credentials(
        self, environ: Mapping[str, str] | None = None
    ) -> tuple[str | None, str | None]:
        """The broker account from the environment: (username, password), None where the
        section names none; :class:`MqttSettingsError` where it names an unset one."""
        env = os.environ if environ is None else environ
        found: list[str | None] = []
        for key, name in (("username_env", self.username_env), ("password_env", self.password_env)):
            if name is None:
                found.append(None)
                continue
            value = env.get(name)
            if not value:
                raise MqttSettingsError(
                    f"mqtt.{key}: the environment variable {name} is not set (the broker"
                    " account pkwbus connects with)"
                )
            found.append(value)
        return found[0], found[1]


def mqtt_report(mqtt: Mqtt, rates: Sequence[float], drives: int) -> Iterator[str]:
    """What MQTT will publish at the configured rates (``check-config``): the values (one
    per poll, each read at ``rates`` a second), each at most once per read and at least once
    per heartbeat, and the ``drives``' statuses."""
    values, reads = len(rates), sum(rates)
    beat, deadband = mqtt.values.heartbeat, mqtt.values.deadband
    least = values / beat
    beyond = "" if deadband == 0 else f" beyond the deadband {deadband:g}"
    yield (
        f"mqtt: {mqtt.url} under {mqtt.prefix}/: {values} value(s) of {drives} drive(s),"
        f" {least:.2f} to {max(reads, least):.1f} messages/s (at least one per value every"
        f" {beat:g} s, at most one per read on change{beyond})"
    )
    extras = [
        f"{drives} drive status(es) retained",
        f"drive events at QoS 1 through an outbox of at most {_bytes(mqtt.outbox.max_bytes)}"
        f" and {mqtt.outbox.max_age / 3600:g} h",
    ]
    if mqtt.homeassistant.discovery:
        ha = mqtt.homeassistant.prefix
        extras.append(f"{drives} Home Assistant device config(s) under {ha}/")
    extras.append("writes " + ("taken on the set topics" if mqtt.writes != "off" else "off"))
    yield "mqtt: " + "; ".join(extras)
    if mqtt.sparkplug is not None:
        yield from sparkplug_report(mqtt, mqtt.sparkplug, drives)


def sparkplug_report(mqtt: Mqtt, sparkplug: Sparkplug, drives: int) -> Iterator[str]:
    """What the Sparkplug B edge node will publish (``check-config``)."""
    node = f"spBv1.0/{sparkplug.group_id}/{{kind}}/{sparkplug.edge_node_id}"
    when = (
        f"while the primary host {sparkplug.primary_host_id} is online"
        f" (spBv1.0/STATE/{sparkplug.primary_host_id})"
        if sparkplug.primary_host_id
        else "at each connection"
    )
    yield (
        f"sparkplug: edge node {node}: NBIRTH {when}, then a DBIRTH per answering drive of"
        f" {drives}, DDATA by exception (the values that changed, per drive), DDEATH/DBIRTH as"
        " drives go and come, NDEATH as the will; bdSeq kept across restarts"
    )
    yield "sparkplug: DCMD " + (
        "written through the write path" if mqtt.writes == "allow_list" else "not taken"
    )


def _bytes(size: int) -> str:
    for unit, scale in (("GiB", 1024**3), ("MiB", 1024**2), ("KiB", 1024)):
        if size >= scale:
            return f"{size / scale:g} {unit}"
    return f"{size} bytes"
