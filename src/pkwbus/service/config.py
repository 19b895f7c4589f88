"""The service's configuration file: strict pydantic models of the YAML in interface.md.

Load it with :func:`load_config`; every problem, whatever its kind (unreadable
file, YAML syntax, duplicate key, unknown setting, wrong value, a parameter
the drive's dialect cannot encode), ends in one :class:`ConfigError` whose
``problems`` name their place::

    lines[0].drives[2].address: 130 is outside 1-126 for protocol fc

Environment:

- the write token is read from the variable named by ``api.write_token_env``
  (default ``PKWBUS_WRITE_TOKEN``) when asked for, with
  :meth:`Config.write_token`; it is never stored in the model, so it never
  shows in a repr, a log line or an error;
- ``PKWBUS_LISTEN`` (HOST:PORT), when set, replaces the file's ``listen``.

Defaults that depend on the line are filled in once the line is valid: a
drive's dialect (``fc`` on an FC line, ``uss`` on a USS line), its IND layout
(the dialect's), its PKW/PZD lengths (USS 4 and 2; FC fixed). The fields keep
what the file said; the resolved values are the properties
:attr:`Drive.protocol`, :attr:`Drive.pkw_dialect`, :attr:`Drive.layout` and
:attr:`Drive.shape`.
"""

from __future__ import annotations

import difflib
import ipaddress
import math
import os
import re
import types
import typing
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Final, Literal, Protocol, Self
from urllib.parse import parse_qsl, urlsplit

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainValidator,
    PrivateAttr,
    StrictBool,
    StrictInt,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from pkwbus import durations
from pkwbus.catalog import CatalogError, ParameterSpec, available_catalogs, load_catalog
from pkwbus.durations import DurationRange, parse_duration
from pkwbus.limits import MAX_RETRIES, check_baudrate, check_port_url
from pkwbus.protocol.dialects import Dialect, IndLayout, dialect
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.params import (
    MAX_INDEX,
    ParameterRef,
    Scaling,
    ValueType,
    canonical,
    parse_parameter,
    parse_type,
    siemens_name,
)
from pkwbus.protocol.telegram import (
    FC_PARAMETER,
    BlockShape,
    FcAddressFormat,
)
from pkwbus.protocol.telegram import (
    Protocol as BusProtocol,
)
from pkwbus.yamlfile import YamlError, load_yaml

DEFAULT_LISTEN: Final = "127.0.0.1:9725"
LISTEN_ENV: Final = "PKWBUS_LISTEN"
DEFAULT_TOKEN_ENV: Final = "PKWBUS_WRITE_TOKEN"
PORT_SCHEMES: Final = frozenset({"socket", "rfc2217", "loop", "spy", "alt", "hwgrep", "sim"})
DIALECTS_BY_PROTOCOL: Final = {
    BusProtocol.FC: ("fc",),
    BusProtocol.USS: ("uss", "profidrive", "danfoss-pcv", "hitachi-sjpb"),
}
USS_MAX_ADDRESS: Final = 30  # ADR bits 0-4 give 0-31; drives accept 0-30
PAUSE_CHARACTERS: Final = 3.5
MAX_CONFIG_BYTES: Final = 1024 * 1024  # a configuration file is read up to this, no further
_NAME = r"^[A-Za-z0-9_.-]+$"
_NAME_MAX = 64


# HTTP connections at most: with the ports, the audit database and the listener
# every descriptor stays below 1024, which pyserial's socket:// handler needs (it
# waits with select()).
MAX_HTTP_CONNECTIONS = 900


class ConfigError(Exception):
    """The configuration cannot be used; ``problems`` has one line per problem."""

    def __init__(self, problems: Sequence[str]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


Place = tuple[str, str]  # (place relative to the model that found it, message)


def _fail(problems: Sequence[Place]) -> PydanticCustomError:
    """One validation error carrying several problems, each with its own place."""
    summary = "; ".join(f"{p}: {m}" if p else m for p, m in problems)
    return PydanticCustomError(
        "pkwbus_problems", "{summary}", {"summary": summary, "problems": list(problems)}
    )


# ------------------------------------------------------------------ scalars


def _number(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{_short(value)} is not a number")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise ValueError(f"{_short(value)} is not a finite number")
    return number


def _notation(value: object) -> ParameterRef:
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)
    if not isinstance(value, str):
        raise ValueError(f"{_short(value)} is not a parameter: write it as 16-13, 1613 or r0021")
    return parse_parameter(value)


def _value_type(value: object) -> ValueType:
    if not isinstance(value, str):
        raise ValueError(f"{_short(value)} is not a type name")
    return parse_type(value)


def _pkw_words(value: object) -> int | None:
    """0, 3 or 4 fixed words; ``variable`` or 127: None."""
    if value == "variable" or (value == 127 and not isinstance(value, bool)):
        return None
    if isinstance(value, int) and not isinstance(value, bool) and value in (0, 3, 4):
        return value
    raise ValueError(f"{_short(value)} is not a PKW length: use 0, 3, 4 or variable (127)")


def _upper(value: object) -> object:
    return value.upper() if isinstance(value, str) else value


def _short(value: object) -> str:
    """A value as shown in a problem: a scalar's repr (shortened), else its kind."""
    if not isinstance(value, str | int | float | bool | None):
        return _kind(value)
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _duration(within: DurationRange) -> PlainValidator:
    """A duration of one kind: its range is in :mod:`pkwbus.durations`' table."""
    return PlainValidator(lambda value: parse_duration(value, within))


Interval = Annotated[float, _duration(durations.POLL_INTERVAL)]
Timeout = Annotated[float, _duration(durations.TELEGRAM_TIMEOUT)]
Pause = Annotated[float, _duration(durations.PAUSE)]
CharTimeout = Annotated[float, _duration(durations.INTER_CHAR_TIMEOUT)]
Delay = Annotated[float, _duration(durations.RESPONSE_DELAY)]
Number = Annotated[float, PlainValidator(_number)]
Notation = Annotated[ParameterRef, PlainValidator(_notation)]
TypeName = Annotated[ValueType, PlainValidator(_value_type)]
PkwWords = Annotated[int | None, PlainValidator(_pkw_words)]
Name = Annotated[str, Field(pattern=_NAME, min_length=1, max_length=_NAME_MAX, strict=True)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# --------------------------------------------------------------- catalogs


class CatalogLike(Protocol):
    """What the config needs of a catalog: ``pkwbus.catalog.Catalog`` has it."""

    def get(self, pnu: int, /) -> ParameterSpec | None: ...


@dataclass(frozen=True)
class Catalogs:
    """Where catalog names are looked up: the built-in ones, or a stand-in for tests.

    ``load(name)`` returns the catalog or raises :class:`LookupError` (unknown
    name) or :class:`ValueError` (a broken catalog), each with a message.
    """

    load: Callable[[str], CatalogLike]
    available: Callable[[], Sequence[str]]


def builtin_catalogs() -> Catalogs:
    """The catalogs shipped in :mod:`pkwbus.catalog`."""

    def load(name: str) -> CatalogLike:
        if name not in available_catalogs():
            raise LookupError(f"unknown catalog {name!r}")
        try:
            return load_catalog(name)
        except CatalogError as exc:
            raise ValueError(f"catalog {name!r} cannot be loaded: {exc}") from None

    def available() -> Sequence[str]:
        return tuple(available_catalogs())

    return Catalogs(load=load, available=available)


def _catalogs(info: ValidationInfo) -> Catalogs:
    context = info.context if isinstance(info.context, dict) else {}
    found = context.get("catalogs")
    return found if isinstance(found, Catalogs) else builtin_catalogs()


# ------------------------------------------------------------- parameters


class ParameterOverrides(_Model):
    """What the config says about a parameter, over its catalog entry."""

    type: TypeName | None = None
    scale: Number | None = None
    conversion: StrictInt | None = None
    unit: str | None = Field(default=None, strict=True)
    min: Number | None = None
    max: Number | None = None
    name: str | None = Field(default=None, strict=True, min_length=1)

    @field_validator("scale")
    @classmethod
    def _scale_not_zero(cls, value: float | None) -> float | None:
        if value == 0:
            raise ValueError("0 is not a scale: it would make every value 0")
        return value

    @field_validator("conversion")
    @classmethod
    def _known_conversion(cls, value: int | None) -> int | None:
        if value is not None:
            Scaling.conversion(value)
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        problems: list[Place] = []
        if self.scale is not None and self.conversion is not None:
            problems.append(("conversion", "give scale or conversion, not both"))
        if self.min is not None and self.max is not None and self.min > self.max:
            problems.append(("min", f"{self.min} is above max {self.max}"))
        if problems:
            raise _fail(problems)
        return self

    @property
    def scaling(self) -> Scaling | None:
        """The configured scaling, None when the config leaves it to the catalog."""
        if self.conversion is not None:
            return Scaling.conversion(self.conversion)
        if self.scale is not None:
            return Scaling.scale(self.scale)
        return None

    def given(self) -> bool:
        """Whether any override is set."""
        return any(getattr(self, key) is not None for key in OVERRIDE_FIELDS)

    def changes(self) -> dict[str, Any]:
        """The overrides that are set, as :meth:`ParameterSpec.overridden` takes them."""
        values = {key: getattr(self, key) for key in OVERRIDE_FIELDS}
        if self.type is not None:
            values["type"] = self.type.value
        return {key: value for key, value in values.items() if value is not None}

    def overrides(self) -> ParameterOverrides:
        """Only the override fields (of a poll entry, say)."""
        values = {key: getattr(self, key) for key in OVERRIDE_FIELDS}
        return ParameterOverrides.model_construct(**values)


OVERRIDE_FIELDS: Final = ("type", "scale", "conversion", "unit", "min", "max", "name")


class Poll(ParameterOverrides):
    """One polled parameter: ``{parameter: "16-13", every: 1s}`` plus optional overrides."""

    parameter: Notation
    every: Interval
    index: StrictInt | None = Field(default=None, ge=0, le=MAX_INDEX)

    @model_validator(mode="after")
    def _index_once(self) -> Self:
        if self.index is not None and self.parameter.index is not None:
            raise _fail([("index", f"the index is already in {self.parameter}: give it once")])
        return self

    @property
    def ref(self) -> ParameterRef:
        """The parameter with its index, from the notation or from ``index``."""
        if self.index is None:
            return self.parameter
        return ParameterRef(self.parameter.pnu, self.index, self.parameter.name)


def _key(ref: ParameterRef) -> tuple[int, int | None]:
    return (ref.pnu, ref.index)


# ------------------------------------------------------------------ drive


class Drive(_Model):
    """One drive (follower) on a line."""

    name: Name
    address: StrictInt
    dialect: str | None = Field(default=None, strict=True)
    ind_layout: IndLayout | None = None
    pkw_words: PkwWords = 4
    pzd_words: StrictInt = Field(default=2, ge=0, le=16)
    catalog: str | None = Field(default=None, strict=True)
    poll: list[Poll] = []
    writable: list[Notation] = []
    parameters: dict[Notation, ParameterOverrides] = {}

    _protocol: BusProtocol = PrivateAttr(default=BusProtocol.FC)

    @field_validator("dialect")
    @classmethod
    def _known_dialect(cls, value: str | None) -> str | None:
        if value is not None:
            dialect(value)
        return value

    @field_validator("catalog")
    @classmethod
    def _known_catalog(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is None:
            return None
        catalogs = _catalogs(info)
        try:
            catalogs.load(value)
        except LookupError:
            known = ", ".join(catalogs.available()) or "none installed"
            raise ValueError(f"unknown catalog {value!r} (available: {known})") from None
        return value

    @model_validator(mode="after")
    def _unique_parameters(self) -> Self:
        problems = _duplicates("poll", [p.ref for p in self.poll], "parameter", "polled")
        problems += _duplicates("writable", self.writable, "", "listed")
        problems += _duplicates("parameters", list(self.parameters), "", "given")
        overridden = {_key(ref) for ref in self.parameters}
        for i, entry in enumerate(self.poll):
            if entry.given() and _key(entry.ref) in overridden:
                problems.append(
                    (f"poll[{i}]", f"{entry.ref} has overrides both here and under parameters")
                )
        if problems:
            raise _fail(problems)
        return self

    @model_validator(mode="after")
    def _fits_catalog(self, info: ValidationInfo) -> Self:
        """Overrides must agree with the catalog entry they change; indexes fit arrays."""
        catalogs = _catalogs(info)
        problems: list[Place] = []
        for place, ref in self.refs():
            try:
                spec = self.spec(ref, catalogs)
            except ValueError as exc:
                problems.append((place, f"{ref}: {str(exc).removeprefix('override: ')}"))
                continue
            if spec and spec.array and ref.index is not None and ref.index >= spec.array:
                problems.append((place, f"{ref}: the catalog gives it {spec.array} elements"))
        for i, ref in enumerate(self.writable):
            if ref.prefix == "r":
                problems.append((f"writable[{i}]", f"{ref} is read-only (r): settable ones are p"))
            elif self._catalog_prefix(ref.pnu, catalogs) == "r":
                name = siemens_name("r", ref.pnu)
                problems.append((f"writable[{i}]", f"{ref} is {name}, read-only (r)"))
        if problems:
            raise _fail(problems)
        return self

    def spec(self, ref: ParameterRef, catalogs: Catalogs | None = None) -> ParameterSpec | None:
        """What is known of ``ref`` on this drive: its catalog entry with the config's overrides.

        From the overrides alone when the catalog lacks it; None when neither
        says anything (the value is read and exported raw). ValueError when
        the overrides do not fit the catalog entry (min above its max, say).
        """
        changes = self.overrides_for(ref).changes()
        base = None
        if self.catalog is not None:
            base = (catalogs or builtin_catalogs()).load(self.catalog).get(ref.pnu)
        if base is None:
            if not changes:
                return None
            base = ParameterSpec(pnu=ref.pnu, name=ref.name)
        return base.overridden(changes) if changes else base

    @property
    def protocol(self) -> BusProtocol:
        return self._protocol

    @property
    def pkw_dialect(self) -> Dialect:
        """The dialect, given or the protocol's default."""
        return dialect(self.dialect or DIALECTS_BY_PROTOCOL[self._protocol][0])

    @property
    def layout(self) -> IndLayout:
        """The IND layout, given or the dialect's default."""
        return self.ind_layout or self.pkw_dialect.default_ind_layout

    @property
    def shape(self) -> BlockShape:
        """The data block of a parameter telegram: FC fixed, USS as configured."""
        if self._protocol is BusProtocol.FC:
            return FC_PARAMETER
        return BlockShape(self.pkw_words, self.pzd_words)

    def refs(self) -> Iterator[tuple[str, ParameterRef]]:
        """Every parameter the drive's config names, with its place."""
        for i, entry in enumerate(self.poll):
            yield f"poll[{i}].parameter", entry.ref
        for i, ref in enumerate(self.writable):
            yield f"writable[{i}]", ref
        for ref in self.parameters:
            yield f"parameters[{ref}]", ref

    def overrides_for(self, ref: ParameterRef) -> ParameterOverrides:
        """The config's overrides for ``ref``: its poll entry's, else ``parameters``'."""
        for entry in self.poll:
            if _key(entry.ref) == _key(ref) and entry.given():
                return entry.overrides()
        for key in (_key(ref), (ref.pnu, None)):
            for given, overrides in self.parameters.items():
                if _key(given) == key:
                    return overrides
        return ParameterOverrides()

    def canonical(self, ref: ParameterRef, catalogs: Catalogs | None = None) -> ParameterRef:
        """``ref`` under this drive's one name for it, as labels, the API and the audit
        show it: ``3-41`` on a Danfoss drive (written ``341`` or ``0341``; r/p is a
        LocalProtocolError), else ``r0021``/``p1082`` with the prefix of the catalog,
        else of this configuration, else the plain number."""
        numbers = self.pkw_dialect.danfoss_numbers
        return canonical(ref, danfoss=numbers, prefix=self._prefix(ref.pnu, catalogs))

    def _prefix(self, pnu: int, catalogs: Catalogs | None) -> str:
        """The r/p of ``pnu``: the catalog's, else the first this configuration writes."""
        given = (ref.prefix for _, ref in self.refs() if ref.pnu == pnu and ref.prefix)
        return self._catalog_prefix(pnu, catalogs) or next(given, "")

    def _catalog_prefix(self, pnu: int, catalogs: Catalogs | None) -> str:
        if self.catalog is None:
            return ""
        spec = (catalogs or builtin_catalogs()).load(self.catalog).get(pnu)
        return spec.prefix if spec is not None else ""

    def may_write(self, ref: ParameterRef) -> bool:
        """Whether ``writable`` lists ``ref`` (an entry without index allows every index)."""
        return any(
            w.pnu == ref.pnu and (w.index is None or w.index == ref.index) for w in self.writable
        )


def _duplicates(field: str, refs: Sequence[ParameterRef], leaf: str, verb: str) -> list[Place]:
    seen: dict[tuple[int, int | None], int] = {}
    problems: list[Place] = []
    for i, ref in enumerate(refs):
        place = f"{field}[{i}]" + (f".{leaf}" if leaf else "")
        if field == "parameters":
            place = f"parameters[{ref}]"
        first = seen.setdefault(_key(ref), i)
        if first != i:
            problems.append((place, f"{ref} is {verb} twice (also {field}[{first}])"))
    return problems


# ------------------------------------------------------------------- line


@dataclass(frozen=True, slots=True)
class SimPort:
    """A ``sim://PROTOCOL?drives=1,2,3&response_delay=3ms`` port: start simulated drives."""

    protocol: BusProtocol
    drives: tuple[int, ...]
    response_delay: float | None = None


def parse_sim_port(url: str) -> SimPort:
    """Parse a ``sim://`` port; ValueError with a plain message when it is malformed."""
    parts = urlsplit(url)
    if parts.scheme != "sim" or parts.path not in ("", "/") or parts.fragment:
        raise ValueError(f"{url!r} is not sim://fc?drives=1,2 or sim://uss?drives=...")
    try:
        protocol = BusProtocol(parts.netloc.lower())
    except ValueError:
        raise ValueError(f"{url!r}: simulated protocol must be fc or uss") from None
    options = _sim_options(url, parts.query)
    if "drives" not in options:
        raise ValueError(f"{url!r}: list the simulated drives, e.g. ?drives=1,2,3")
    drives = _address_list(url, options["drives"])
    delay = options.get("response_delay")
    if delay is None:
        return SimPort(protocol, drives)
    try:
        return SimPort(protocol, drives, parse_duration(delay, durations.RESPONSE_DELAY))
    except ValueError as exc:
        raise ValueError(f"{url!r}: response_delay {exc}") from None


def _sim_options(url: str, query: str) -> dict[str, str]:
    try:
        pairs = parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query))
    except ValueError:
        raise ValueError(f"{url!r}: options must be key=value&key=value") from None
    options: dict[str, str] = {}
    for key, value in pairs:
        if key not in ("drives", "response_delay"):
            raise ValueError(f"{url!r}: unknown option {key!r} (known: drives, response_delay)")
        if key in options:
            raise ValueError(f"{url!r}: option {key!r} is given twice")
        options[key] = value
    return options


def _address_list(url: str, text: str) -> tuple[int, ...]:
    addresses: list[int] = []
    for item in text.split(","):
        low, _, high = item.strip().partition("-")
        if not low.isdigit() or not (high or low).isdigit() or len(item) > 7:
            raise ValueError(f"{url!r}: drives must be addresses like 1,2,5-7, not {item!r}")
        addresses.extend(range(int(low), int(high or low) + 1))
    if any(a > 126 for a in addresses) or not addresses:
        raise ValueError(f"{url!r}: simulated drive addresses must be 0-126")
    return tuple(addresses)


def _check_port(value: str) -> str:
    if not value.strip() or any(ord(c) < 0x20 for c in value):
        raise ValueError(
            "must be a device path such as /dev/ttyUSB0 or a URL such as socket://host:port"
        )
    if "://" in value:
        scheme = value.split("://", 1)[0].lower()
        if scheme not in PORT_SCHEMES:
            known = ", ".join(f"{s}://" for s in sorted(PORT_SCHEMES))
            raise ValueError(f"unknown port URL scheme {scheme!r} (known: {known})")
        if scheme == "sim":
            parse_sim_port(value)
        check_port_url(value)
    return value


def _rs485_delay(value: object) -> float:
    """An RTS delay: the kernel takes whole milliseconds, so 0.5ms would silently be 0."""
    seconds = parse_duration(value, durations.RS485_DELAY)
    if abs(seconds * 1000 - round(seconds * 1000)) > 1e-9:
        raise ValueError(f"{_short(value)}: the kernel counts RS-485 delays in whole milliseconds")
    return seconds


class Rs485(_Model):
    """Kernel RS-485 mode of a native UART: the driver switches RTS around each transmission."""

    rts_level_for_tx: StrictBool = True
    rts_level_for_rx: StrictBool = False
    delay_before_tx: Annotated[float, PlainValidator(_rs485_delay)] = 0.0
    delay_before_rx: Annotated[float, PlainValidator(_rs485_delay)] = 0.0


class Line(_Model):
    """One RS-485 line: its port, framing and timing, and the drives on it."""

    name: Name
    port: Annotated[str, Field(strict=True)]
    protocol: BusProtocol
    baudrate: StrictInt
    parity: Annotated[Literal["E", "O", "N"], BeforeValidator(_upper)] = "E"
    stopbits: Literal[1, 2] = 1
    timeout: Timeout = 0.1
    retries: StrictInt = Field(default=2, ge=0, le=MAX_RETRIES)
    pause: Pause | None = None
    inter_char_timeout: CharTimeout | None = None
    response_delay: Delay | None = None
    echo: StrictBool = False
    fc_address_format: FcAddressFormat | None = None
    low_latency: StrictBool = False  # ask the adapter's driver for 1 ms latency
    rs485: Rs485 | None = None  # kernel RS-485 mode (native UARTs)
    drives: list[Drive] = Field(min_length=1)

    @field_validator("port")
    @classmethod
    def _port(cls, value: str) -> str:
        return _check_port(value)

    @field_validator("rs485")
    @classmethod
    def _rs485_on_a_device(cls, value: Rs485 | None, info: ValidationInfo) -> Rs485 | None:
        port = info.data.get("port")
        if value is not None and isinstance(port, str) and "://" in port:
            raise ValueError(f"applies to a serial device such as /dev/ttyS1, not {_short(port)}")
        return value

    @field_validator("baudrate")
    @classmethod
    def _baudrate(cls, value: int) -> int:
        return check_baudrate(value)

    @model_validator(mode="after")
    def _drives_fit_line(self) -> Self:
        problems = self._line_problems()
        for i, drive in enumerate(self.drives):
            problems += [(f"drives[{i}].{p}", m) for p, m in _drive_problems(self, drive)]
        problems += self._address_problems()
        if problems:
            raise _fail(problems)
        for drive in self.drives:
            drive._protocol = self.protocol
        return self

    def _line_problems(self) -> list[Place]:
        problems: list[Place] = []
        if self.protocol is BusProtocol.USS and self.fc_address_format is not None:
            problems.append(("fc_address_format", "applies to protocol fc only"))
        sim = self.sim
        if sim is not None:
            if sim.protocol is not self.protocol:
                problems.append(
                    ("port", f"simulates protocol {sim.protocol} but the line's is {self.protocol}")
                )
            missing = sorted({d.address for d in self.drives} - set(sim.drives))
            if missing:
                listed = ",".join(str(a) for a in missing)
                problems.append(("port", f"simulates no drive at address {listed}"))
        return problems

    def _address_problems(self) -> list[Place]:
        problems: list[Place] = []
        seen: dict[int, str] = {}
        for i, drive in enumerate(self.drives):
            first = seen.setdefault(drive.address, drive.name)
            if first != drive.name:
                problems.append(
                    (f"drives[{i}].address", f"address {drive.address} is already used by {first}")
                )
        return problems

    @property
    def address_format(self) -> FcAddressFormat:
        return self.fc_address_format or FcAddressFormat.RANGE_1_126

    @property
    def address_range(self) -> tuple[int, int]:
        if self.protocol is BusProtocol.USS:
            return (0, USS_MAX_ADDRESS)
        return (1, 31) if self.address_format is FcAddressFormat.RANGE_1_31 else (1, 126)

    @property
    def sim(self) -> SimPort | None:
        """The simulated drives this line asks for, None for a real port."""
        if not self.port.lower().startswith("sim://"):
            return None
        return parse_sim_port(self.port)

    @property
    def bits_per_character(self) -> int:
        """Start bit, 8 data bits, parity bit unless N, stop bits: 11 with the default 8E1."""
        return 1 + 8 + (0 if self.parity == "N" else 1) + self.stopbits

    @property
    def character_time(self) -> float:
        return self.bits_per_character / self.baudrate

    @property
    def pause_seconds(self) -> float:
        """Pause before each request: as configured, else 3.5 character times."""
        return self.pause if self.pause is not None else PAUSE_CHARACTERS * self.character_time

    @property
    def inter_char_seconds(self) -> float:
        """A gap longer than this ends a telegram: as configured, else the pause."""
        if self.inter_char_timeout is not None:
            return self.inter_char_timeout
        return self.pause_seconds

    @property
    def response_delay_seconds(self) -> float | None:
        """The expected response delay: configured, else the simulator's, else None."""
        if self.response_delay is not None:
            return self.response_delay
        sim = self.sim
        return sim.response_delay if sim is not None else None


def _drive_problems(line: Line, drive: Drive) -> list[Place]:
    problems: list[Place] = []
    low, high = line.address_range
    if not low <= drive.address <= high:
        where = f"protocol {line.protocol}"
        if line.fc_address_format is FcAddressFormat.RANGE_1_31:
            where += " with fc_address_format 1-31"
        problems.append(("address", f"{drive.address} is outside {low}-{high} for {where}"))
    allowed = DIALECTS_BY_PROTOCOL[line.protocol]
    if drive.dialect is not None and drive.dialect not in allowed:
        problems.append(
            (
                "dialect",
                f"{drive.dialect} is not for protocol {line.protocol} (use {', '.join(allowed)})",
            )
        )
        return problems
    if line.protocol is BusProtocol.FC:
        for key in ("pkw_words", "pzd_words"):
            if key in drive.model_fields_set:
                problems.append(
                    (key, "applies to protocol uss only: FC telegrams have a fixed shape")
                )
    elif drive.pkw_words == 0 and (drive.poll or drive.writable):
        problems.append(("pkw_words", "is 0: the drive has no parameter channel to poll or write"))
    problems += _pnu_problems(drive, dialect(drive.dialect or allowed[0]))
    return problems


def _pnu_problems(drive: Drive, pkw_dialect: Dialect) -> list[Place]:
    """Numbers the dialect cannot encode; notation the drive does not use (r/p on a
    Danfoss drive, r0021 and p0021 both)."""
    problems: list[Place] = []
    prefixes: dict[int, ParameterRef] = {}
    for place, ref in drive.refs():
        try:
            pkw_dialect.check_pnu(ref.pnu)
        except LocalProtocolError as exc:
            problems.append((place, f"{ref}: {exc}"))
            continue
        try:
            canonical(ref, danfoss=pkw_dialect.danfoss_numbers)
        except LocalProtocolError as exc:
            problems.append((place, str(exc)))
            continue
        first = prefixes.setdefault(ref.pnu, ref) if ref.prefix else ref
        if first.prefix != ref.prefix:
            problems.append((place, f"{ref} and {first} name one parameter: write it one way"))
    return problems


# ------------------------------------------------------------------- top


class Listen(_Model):
    """Where the HTTP server listens: written ``HOST:PORT`` or ``[IPv6]:PORT``."""

    host: str
    port: StrictInt = Field(ge=1, le=65535)

    @model_validator(mode="before")
    @classmethod
    def _from_text(cls, value: object) -> object:
        if isinstance(value, str):
            host, port = parse_listen(value)
            return {"host": host, "port": port}
        if isinstance(value, Listen | dict):
            return value
        raise ValueError(f"{_short(value)} is not HOST:PORT (e.g. 127.0.0.1:9725 or [::1]:9725)")

    @field_validator("host")
    @classmethod
    def _host(cls, value: str) -> str:
        return _check_host(value)

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"


_HOSTNAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9.-]{0,252}$")
_LISTEN_HINT = "write HOST:PORT, e.g. 127.0.0.1:9725, 0.0.0.0:9725 or [::1]:9725"


def _check_host(host: str) -> str:
    """A host name, an IPv4 address or a bare IPv6 address."""
    if ":" in host:
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise ValueError(f"{host!r} is not an IPv6 address") from None
    elif not _HOSTNAME.match(host):
        raise ValueError(f"{host!r} is not a host name or address: {_LISTEN_HINT}")
    return host


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` or ``[IPv6]:PORT`` as (host, port); ValueError otherwise."""
    head, sep, port_text = text.strip().rpartition(":")
    if not sep or not head:
        raise ValueError(f"{_short(text)} is not HOST:PORT: {_LISTEN_HINT}")
    bracketed = head.startswith("[") and head.endswith("]")
    if ":" in head and not bracketed:
        raise ValueError(f"{_short(text)}: write an IPv6 address in brackets, e.g. [::1]:9725")
    try:
        host = _check_host(head[1:-1] if bracketed else head)
        if bracketed and ":" not in host:
            raise ValueError(f"{host!r} is not an IPv6 address")
    except ValueError as exc:
        raise ValueError(f"{_short(text)}: {exc}") from None
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise ValueError(f"{_short(text)}: port must be a number 1-65535")
    return host, int(port_text)


_ENV_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,127}$")


def _env_name(value: object) -> str:
    if not isinstance(value, str) or not _ENV_NAME.match(value):
        raise ValueError(
            f"{_short(value)} is not an environment variable name (letters, digits and _)"
        )
    return value


class Api(_Model):
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


class Config(_Model):
    """The whole file."""

    listen: Listen = Listen.model_validate(DEFAULT_LISTEN)
    api: Api = Api()
    audit_db: Annotated[Path, PlainValidator(_audit_path)] = Path("var/audit.sqlite")
    log_format: Literal["text", "json"] = "text"
    lines: list[Line] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique_names(self) -> Self:
        problems: list[Place] = []
        lines: dict[str, int] = {}
        drives: dict[str, str] = {}
        for i, line in enumerate(self.lines):
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
        if problems:
            raise _fail(problems)
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

    def drives(self) -> Iterator[tuple[Line, Drive]]:
        for line in self.lines:
            for drive in line.drives:
                yield line, drive

    def drive(self, name: str) -> tuple[Line, Drive] | None:
        return next(((ln, d) for ln, d in self.drives() if d.name == name), None)

    def with_listen(self, text: str) -> Config:
        """The same config listening elsewhere (``--listen``); ConfigError when malformed."""
        try:
            return self.model_copy(update={"listen": Listen.model_validate(text)})
        except ValidationError as exc:
            raise ConfigError([f"--listen: {_plain(e)}" for e in exc.errors()]) from None


# ---------------------------------------------------------------- loading


def load_config(
    path: str | os.PathLike[str],
    *,
    environ: Mapping[str, str] | None = None,
    catalogs: Catalogs | None = None,
) -> Config:
    """Read and check a configuration file; :class:`ConfigError` for any problem."""
    shown = os.fspath(path)
    try:
        with Path(path).open("rb") as file:  # a device or a pipe too, but never more than the cap
            data = file.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError([f"{shown}: cannot read: {exc.strerror or exc}"]) from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(
            [f"{shown}: larger than {MAX_CONFIG_BYTES >> 20} MiB: not a pkwbus configuration"]
        )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError([f"{shown}: not UTF-8 text (byte {exc.start})"]) from None
    return parse_config(text, environ=environ, catalogs=catalogs)


def parse_config(
    text: str,
    *,
    environ: Mapping[str, str] | None = None,
    catalogs: Catalogs | None = None,
) -> Config:
    """Check configuration text (what :func:`load_config` does after reading the file)."""
    data = _parse_yaml(text)
    env = os.environ if environ is None else environ
    listen = env.get(LISTEN_ENV)
    if listen:
        data = {**data, "listen": listen}
    context = {"catalogs": catalogs or builtin_catalogs()}
    try:
        return Config.model_validate(data, context=context)
    except ValidationError as exc:
        raise ConfigError(_problems(exc, listen_from_env=bool(listen))) from None
    except RecursionError:
        raise ConfigError(["the file nests too deeply"]) from None


def _parse_yaml(text: str) -> dict[str, Any]:
    try:
        data = load_yaml(text)
    except YamlError as exc:
        raise ConfigError([str(exc)]) from None
    if data is None:
        raise ConfigError(["the file is empty: it needs at least lines:"])
    if not isinstance(data, dict):
        raise ConfigError([f"the top level must be a mapping (key: value), not {_kind(data)}"])
    return data


def _kind(value: object) -> str:
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, str):
        return "text"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, int | float):
        return "a number"
    return f"a {type(value).__name__}"


# ------------------------------------------------------ problems in words


def _problems(exc: ValidationError, *, listen_from_env: bool) -> list[str]:
    out: list[str] = []
    for error in exc.errors(include_url=False):
        base = _place(error["loc"])
        if listen_from_env and base.startswith("listen"):
            base = f"{LISTEN_ENV} (overrides listen)"
        if error["type"] == "pkwbus_problems":
            for place, message in error.get("ctx", {}).get("problems", []):
                out.append(f"{_join(base, place)}: {message}")
        else:
            out.append(f"{base or 'config'}: {_plain(error)}")
    return out


def _join(base: str, place: str) -> str:
    if not base:
        return place or "config"
    return f"{base}.{place}" if place else base


_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _place(loc: Sequence[int | str]) -> str:
    """``('lines', 0, 'drives', 2, 'address')`` as ``lines[0].drives[2].address``."""
    text = ""
    previous: int | str = ""
    for item in loc:
        if item == "[key]":
            continue
        if isinstance(item, int) or previous == "parameters":
            text += f"[{item}]"
        elif not item:
            text += "['']"
        elif _IDENT.match(item):
            text += f".{item}" if text else item
        else:
            text += f"[{item}]"
        previous = item
    return text


_WORDS: Final = {
    "missing": "is required",
    "string_type": "must be text",
    "int_type": "must be a whole number",
    "int_parsing": "must be a whole number",
    "int_from_float": "must be a whole number",
    "float_type": "must be a number",
    "bool_type": "must be true or false",
    "list_type": "must be a list",
    "dict_type": "must be a mapping (key: value)",
    "model_type": "must be a mapping (key: value)",
    "model_attributes_type": "must be a mapping (key: value)",
    "string_pattern_mismatch": "may contain only letters, digits and _ . -",
    "string_too_short": "must not be empty",
    "string_too_long": "is too long",
    "too_short": "must not be empty",
    "recursion_loop": "refers to itself",
}
_SCALAR = (str, int, float, bool, type(None))
_NO_INPUT: Final = frozenset({"missing", "too_short", "string_too_short", "string_too_long"})
_BOUNDS: Final = {
    "greater_than_equal": "must be {ge} or more",
    "greater_than": "must be more than {gt}",
    "less_than_equal": "must be {le} or less",
    "less_than": "must be less than {lt}",
}


def _plain(error: Mapping[str, Any]) -> str:
    """A pydantic error's message in plain words."""
    kind = error["type"]
    if kind == "extra_forbidden":
        return _unknown_setting(error["loc"])
    if kind in ("value_error", "assertion_error"):
        return str(error["msg"]).removeprefix("Value error, ").removeprefix("Assertion failed, ")
    if kind in _BOUNDS:
        bound = _BOUNDS[kind].format(**error.get("ctx", {}))
        return f"{bound}, not {_short(error.get('input'))}"
    message = _WORDS.get(kind) or str(error["msg"]).replace("Input should be", "must be")
    if kind in _NO_INPUT:
        return message
    value = error.get("input")
    return f"{message}, not {_short(value) if isinstance(value, _SCALAR) else _kind(value)}"


def _unknown_setting(loc: Sequence[int | str]) -> str:
    known = _known_keys(loc[:-1])
    if not known:
        return "is not a known setting"
    close = difflib.get_close_matches(str(loc[-1]), known, n=1)
    if close:
        return f"is not a known setting; did you mean {close[0]}?"
    return f"is not a known setting (known: {', '.join(known)})"


def _known_keys(loc: Sequence[int | str]) -> list[str]:
    model: type[BaseModel] = Config
    for item in loc:
        if isinstance(item, str) and item in model.model_fields:
            inner = _model_in(model.model_fields[item].annotation)
            if inner is None:
                return []
            model = inner
    return list(model.model_fields)


def _model_in(annotation: object) -> type[BaseModel] | None:
    """The model class inside ``list[X]``, ``dict[K, X]``, ``X | None``, ``Annotated[X, ...]``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    origin = typing.get_origin(annotation)
    if origin is None and not isinstance(annotation, types.UnionType):
        return None
    for arg in reversed(typing.get_args(annotation)):
        found = _model_in(arg)
        if found is not None:
            return found
    return None
