"""The whole file: where the API listens, its tokens, the audit log, the lines (each of
its bus's class, picked by its ``protocol``), hot standby (``standby:``).

Raises :class:`~pkwbus.service.config.base.ConfigError` for a malformed ``--listen``.
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Annotated, Final, Literal, Self, TypeAlias
from urllib.parse import urlsplit

from pydantic import (
    BeforeValidator,
    Field,
    PlainValidator,
    StrictInt,
    ValidationError,
    ValidatorFunctionWrapHandler,
    WrapValidator,
    field_validator,
    model_validator,
)

from pkwbus.link import same_line
from pkwbus.notation.durations import STANDBY_LEASE, parse_duration
from pkwbus.notation.hostport import ANY_FREE_PORT, MAX_TCP_PORT, check_host, parse_host_port
from pkwbus.notation.problems import plain, short
from pkwbus.protocol.buses import Bus
from pkwbus.service.config.base import (
    DEFAULT_LISTEN,
    DEFAULT_TOKEN_ENV,
    MAX_HTTP_CONNECTIONS,
    ConfigError,
    Model,
    Place,
    fail,
    placed,
)
from pkwbus.service.config.fields import Retention
from pkwbus.service.config.line import LineBase
from pkwbus.service.config.mqtt import Mqtt, ha_id_clashes
from pkwbus.service.config.profibus import ProfibusDrive
from pkwbus.service.config.profibus_line import ProfibusLine
from pkwbus.service.config.serial import FcDrive, FcLine, UssDrive, UssLine

__all__ = [
    "ADVERTISE_ENV",
    "INSTANCE_ENV",
    "LINES",
    "Api",
    "Config",
    "Drive",
    "Line",
    "Listen",
    "StandbyConfig",
    "StandbySection",
    "default_instance_name",
    "parse_listen",
]

# The class of each bus's lines, as the union below picks it by the line's ``protocol``.
LINES: Final[Mapping[Bus, type[FcLine | UssLine | ProfibusLine]]] = {
    Bus.FC: FcLine,
    Bus.USS: UssLine,
    Bus.PROFIBUS: ProfibusLine,
}


def _bus(data: dict[object, object]) -> Bus:
    """The line's bus; its ``protocol`` told as the one place of a problem otherwise."""
    if "protocol" not in data:
        raise fail([("protocol", "is required")])
    given = data["protocol"]
    if not isinstance(given, str) or given not in {p.value for p in LINES}:
        names = [repr(p.value) for p in LINES]
        known = f"{', '.join(names[:-1])} or {names[-1]}"
        raise fail([("protocol", f"must be {known}, not {short(given)}")])
    return Bus(given)


def _bus_line(data: object, handler: ValidatorFunctionWrapHandler) -> object:
    """A line as its bus's class makes it, its problems placed as the file has them: a
    protocol that names no bus is told so, and no place names the union's tag."""
    if isinstance(data, LineBase):
        return handler(data)
    if not isinstance(data, dict):
        raise fail([("", f"must be a mapping (key: value), not {short(data)}")])
    bus = _bus(data)
    try:
        return handler(data)
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        for error in errors:
            if error["loc"][:1] == (bus.value,):
                error["loc"] = error["loc"][1:]
        raise fail(placed(errors, LINES[bus])) from None


# One line of the file: the class of its bus, picked by its ``protocol``.
Line: TypeAlias = Annotated[
    FcLine | UssLine | ProfibusLine, Field(discriminator="protocol"), WrapValidator(_bus_line)
]
# One drive of the file: the class of its line's bus.
Drive: TypeAlias = FcDrive | UssDrive | ProfibusDrive


class Listen(Model):
    """Where the HTTP server listens: written ``HOST:PORT`` or ``[IPv6]:PORT``."""

    host: str
    port: StrictInt = Field(ge=ANY_FREE_PORT, le=MAX_TCP_PORT)  # 0: the system chooses

    @model_validator(mode="before")
    @classmethod
    def _from_text(cls, value: object) -> object:
        if isinstance(value, str):
            host, port = parse_listen(value)
            return {"host": host, "port": port}
        if isinstance(value, Listen | dict):
            return value
        raise ValueError(f"{short(value)} is not HOST:PORT (e.g. 127.0.0.1:9725 or [::1]:9725)")

    @field_validator("host")
    @classmethod
    def _host(cls, value: str) -> str:
        return check_host(value)

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` or ``[IPv6]:PORT`` as (host, port), port 0-65535 (0: any free port,
    which the service's log line "metrics on" names); ValueError otherwise
    (:func:`pkwbus.notation.hostport.parse_host_port`)."""
    return parse_host_port(text, lowest_port=ANY_FREE_PORT)


_ENV_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,127}$")


def _env_name(value: object) -> str:
    if not isinstance(value, str) or not _ENV_NAME.match(value):
        raise ValueError(
            f"{short(value)} is not an environment variable name (letters, digits and _)"
        )
    return value


class Api(Model):
    write_token_env: Annotated[str, PlainValidator(_env_name)] = DEFAULT_TOKEN_ENV
    # HTTP connections open at once; more are closed at once (logged), so a flood of
    # clients cannot take the descriptors the serial ports need.
    max_connections: int = Field(default=500, ge=1, le=MAX_HTTP_CONNECTIONS)
    # A token that may read the audit log (GET /api/v1/audit) but not write; the
    # write token reads it too.
    read_token_env: Annotated[str, PlainValidator(_env_name)] | None = None


def _audit_path(value: object) -> Path:
    if not isinstance(value, str) or not value.strip() or "\x00" in value:
        raise ValueError("must be a file path such as var/audit.sqlite")
    return Path(value)


def _what(port: str) -> str:
    return "gateway port" if same_line(port).startswith("tcp:") else "device"


INSTANCE_ENV: Final = "PKWBUS_INSTANCE"
ADVERTISE_ENV: Final = "PKWBUS_ADVERTISE"

_INSTANCE_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
_PREFIX = re.compile(r"^(/[A-Za-z0-9_.-]+)+$")
_MAX_ENDPOINTS = 16


def default_instance_name() -> str:
    """This instance's name when the section gives none: ``PKWBUS_INSTANCE``, else the
    host name."""
    return os.environ.get(INSTANCE_ENV) or socket.gethostname()


def _url(value: object, what: str) -> str:
    """An ``http://host:port`` or ``https://host:port`` address, as written (less a
    trailing slash)."""
    sample = "http://etcd-0:2379" if what == "an etcd endpoint" else "http://10.0.0.5:9725"
    example = f"write {what} as http://host:port, e.g. {sample}"
    if not isinstance(value, str):
        raise ValueError(f"{short(value)} is not a URL: {example}")
    text = value.strip().rstrip("/")
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError:
        raise ValueError(f"{short(value)} is not a URL: {example}") from None
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError(f"{short(value)} is not a URL: {example}")
    if parts.query or parts.fragment or parts.username or parts.password:
        raise ValueError(f"{short(value)}: {what} takes no user, query or fragment")
    if what == "an etcd endpoint" and (parts.path or port is None):
        raise ValueError(f"{short(value)} is not an etcd endpoint: {example}")
    return text


def _endpoints(value: object) -> list[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value:
        raise ValueError(
            "must list etcd's client URLs, e.g. [http://etcd-0:2379, http://etcd-1:2379]"
        )
    if len(value) > _MAX_ENDPOINTS:
        raise ValueError(f"lists {len(value)} endpoints; at most {_MAX_ENDPOINTS}")
    urls = [_url(v, "an etcd endpoint") for v in value]
    if len(set(urls)) != len(urls):
        raise ValueError("names an endpoint twice")
    return urls


def _lease(value: object) -> float:
    return parse_duration(value, STANDBY_LEASE)


def default_advertise() -> str | None:
    """This instance's URL when the section gives none: ``PKWBUS_ADVERTISE``, else none."""
    return os.environ.get(ADVERTISE_ENV) or None


def _advertise(value: object) -> str | None:
    if isinstance(value, str) and ("{" in value or "}" in value):
        raise ValueError(
            f"{short(value)} is not an address to advertise: the one placeholder is {{name}},"
            " the instance's name (write http://{name}:9725 or http://10.0.0.5:9725)"
        )
    return None if value is None else _url(value, "advertise")


# ---------------------------------------------------------------- standby:
# Hot standby of the lines over etcd (interface "Hot standby"). Absent, ``off`` (which
# YAML also reads as false) or empty: one instance, as before (``Config.standby`` None).


class StandbyConfig(Model):
    """Hot standby: the lines' leases in etcd, this instance's name and address."""

    etcd: Annotated[list[str], PlainValidator(_endpoints)]
    lease: Annotated[float, PlainValidator(_lease)]
    prefix: str = "/pkwbus"
    name: str = Field(default_factory=default_instance_name, validate_default=True)
    advertise: Annotated[str | None, PlainValidator(_advertise)] = Field(
        default_factory=default_advertise, validate_default=True
    )

    @field_validator("prefix", mode="plain")
    @classmethod
    def _prefix(cls, value: object) -> str:
        if not isinstance(value, str) or not _PREFIX.match(value):
            raise ValueError(
                f"{short(value)} is not a key prefix: write /pkwbus or /site/hall-a"
                " (a slash, then letters, digits, _ . -; no trailing slash)"
            )
        return value

    @field_validator("name", mode="plain")
    @classmethod
    def _name(cls, value: object) -> str:
        if not isinstance(value, str) or not _INSTANCE_NAME.match(value):
            raise ValueError(
                f"{short(value)} is not an instance name (1 to 64 letters, digits, _ . -);"
                f" set `name` or {INSTANCE_ENV}"
            )
        return value

    @model_validator(mode="before")
    @classmethod
    def _advertised(cls, data: object) -> object:
        """``{name}`` in ``advertise`` (or ``PKWBUS_ADVERTISE``) replaced by the instance's
        name, so that instances sharing one file each advertise their own address; any
        other placeholder is left for the field's check to refuse."""
        if not isinstance(data, dict):
            return data
        address = data.get("advertise", default_advertise())
        name = data.get("name") or default_instance_name()
        if isinstance(address, str) and isinstance(name, str):
            with contextlib.suppress(KeyError, IndexError, ValueError):
                data = {**data, "advertise": address.format(name=name)}
        return data


def _off(value: object) -> object:
    """``off`` (YAML 1.1 reads it as false), or nothing: no hot standby."""
    if value is None or value is False or value == "off" or value == {}:
        return None
    if value is True or value == "on":
        raise ValueError("needs its settings: etcd (the endpoints) and lease, e.g. 6s")
    return value


# The field of the whole file: None without hot standby.
StandbySection: TypeAlias = Annotated[StandbyConfig | None, BeforeValidator(_off)]


class Config(Model):
    """The whole file."""

    listen: Listen = Listen.model_validate(DEFAULT_LISTEN)
    api: Api = Api()
    audit_db: Annotated[Path, PlainValidator(_audit_path)] = Path("var/audit.sqlite")
    # The drives' own log entries, kept (None: history.sqlite beside the audit log).
    history_db: Annotated[Path, PlainValidator(_audit_path)] | None = None
    history_retention: Retention = 8760 * 3600.0  # a year
    log_format: Literal["text", "json"] = "text"
    lines: list[Line] = Field(min_length=1)
    standby: StandbySection = None  # hot standby over etcd; None: one instance
    mqtt: Mqtt | None = None  # the plant's broker (absent: no MQTT)

    @model_validator(mode="after")
    def _unique_names(self) -> Self:
        problems: list[Place] = []
        lines: dict[str, int] = {}
        drives: dict[str, str] = {}
        ports: dict[str, int] = {}
        for i, line in enumerate(self.lines):
            first_port = ports.setdefault(same_line(line.port), i)
            if first_port != i:
                other = self.lines[first_port]
                problems.append(
                    (
                        f"lines[{i}].port",
                        f"{line.port} is the same {_what(line.port)} as lines[{first_port}]"
                        f" ({other.name}): {other.port}; two masters on one RS-485 line would"
                        " collide",
                    )
                )
            first_line = lines.setdefault(line.name, i)
            if first_line != i:
                problems.append(
                    (
                        f"lines[{i}].name",
                        f"line name {line.name!r} is already used by lines[{first_line}]",
                    )
                )
            for j, drive in enumerate(line.drives):
                place = f"lines[{i}].drives[{j}]"
                first = drives.setdefault(drive.name, place)
                if first != place:
                    problems.append(
                        (f"{place}.name", f"drive name {drive.name!r} is already used at {first}")
                    )
        named = ((f"lines[{i}].drives[{j}]", line.name, drive.name)
                 for i, line in enumerate(self.lines)
                 for j, drive in enumerate(line.drives))  # fmt: skip
        problems += ha_id_clashes(self.mqtt, named)
        if problems:
            raise fail(problems)
        return self

    def write_token(self, environ: Mapping[str, str] | None = None) -> str | None:
        """The API write token from the environment; None (writes refused) when unset or empty."""
        token = (os.environ if environ is None else environ).get(self.api.write_token_env)
        return token or None

    def read_token(self, environ: Mapping[str, str] | None = None) -> str | None:
        """The audit read token from the environment; None when not configured, unset or empty."""
        if self.api.read_token_env is None:
            return None
        return (os.environ if environ is None else environ).get(self.api.read_token_env) or None

    @property
    def history_path(self) -> Path:
        """Where the drives' own log entries are kept: ``history_db``, else beside the
        audit log."""
        return self.history_db or self.audit_db.with_name("history.sqlite")

    def drives(self) -> Iterator[tuple[Line, Drive]]:
        for line in self.lines:
            for drive in line.drives:
                yield line, drive

    def with_listen(self, text: str) -> Config:
        """The same config listening elsewhere (``--listen``); ConfigError when malformed."""
        try:
            return self.model_copy(update={"listen": Listen.model_validate(text)})
        except ValidationError as exc:
            raise ConfigError([f"--listen: {plain(e, Config)}" for e in exc.errors()]) from None
