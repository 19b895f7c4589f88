"""The configuration's field types: durations of each kind, numbers, parameter notation,
type names, PKW lengths, names. Each validator raises ValueError with a plain message."""

from __future__ import annotations

import math
import re
from typing import Annotated, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
)

from pkwbus.notation import durations
from pkwbus.notation.durations import DurationRange, parse_duration
from pkwbus.notation.problems import short
from pkwbus.protocol import buses
from pkwbus.protocol.pkw.length import PkwSetting
from pkwbus.protocol.values import (
    ParameterRef,
    ValueType,
    parse_parameter,
    parse_type,
)

__all__ = [
    "Alarms",
    "CharTimeout",
    "Counters",
    "Delay",
    "Describe",
    "Events",
    "EventsEvery",
    "Interval",
    "Name",
    "Notation",
    "Number",
    "Pause",
    "PkwWords",
    "Retention",
    "Rs485Delay",
    "Settings",
    "SettingsEvery",
    "SettingsField",
    "SlotTime",
    "Timeout",
    "TypeName",
    "Watchdog",
    "upper",
]


_NAME = r"^[A-Za-z0-9_.-]+$"
_NAME_MAX = 64


# A number in exponent form without a point (1e3, 5E-2): YAML 1.1, as PyYAML reads it,
# takes it for text, though any reader of the file sees a number.
_EXPONENT = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+")


def _number(value: object) -> float:
    if isinstance(value, str) and _EXPONENT.fullmatch(value.strip()):
        value = float(value)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{short(value)} is not a number")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise ValueError(f"{short(value)} is not a finite number")
    return number


def _notation(value: object) -> ParameterRef:
    if isinstance(value, int) and not isinstance(value, bool):
        value = str(value)
    if not isinstance(value, str):
        raise ValueError(f"{short(value)} is not a parameter: write it as 16-13, 1613 or r0021")
    return parse_parameter(value)


def _value_type(value: object) -> ValueType:
    if not isinstance(value, str):
        raise ValueError(f"{short(value)} is not a type name")
    return parse_type(value)


def upper(value: object) -> object:
    return value.upper() if isinstance(value, str) else value


def _duration(within: DurationRange) -> PlainValidator:
    """A duration of one kind: its range is in :mod:`pkwbus.notation.durations`' table."""
    return PlainValidator(lambda value: parse_duration(value, within))


Interval = Annotated[float, _duration(durations.POLL_INTERVAL)]
Timeout = Annotated[float, _duration(durations.TELEGRAM_TIMEOUT)]
Pause = Annotated[float, _duration(durations.PAUSE)]
CharTimeout = Annotated[float, _duration(durations.INTER_CHAR_TIMEOUT)]
Delay = Annotated[float, _duration(durations.RESPONSE_DELAY)]
SlotTime = Annotated[float, _duration(durations.DP_SLOT_TIME)]
Watchdog = Annotated[float, _duration(durations.DP_WATCHDOG)]
EventsEvery = Annotated[float, _duration(durations.EVENTS_EVERY)]
Retention = Annotated[float, _duration(durations.HISTORY_RETENTION)]
SettingsEvery = Annotated[float, _duration(durations.SETTINGS_EVERY)]


def _rs485_delay(value: object) -> float:
    """An RTS delay: the kernel takes whole milliseconds, so 0.5ms would silently be 0."""
    seconds = parse_duration(value, durations.RS485_DELAY)
    if abs(seconds * 1000 - round(seconds * 1000)) > 1e-9:
        raise ValueError(f"{short(value)}: the kernel counts RS-485 delays in whole milliseconds")
    return seconds


Rs485Delay = Annotated[float, PlainValidator(_rs485_delay)]
Number = Annotated[float, PlainValidator(_number)]
Notation = Annotated[ParameterRef, PlainValidator(_notation)]
TypeName = Annotated[ValueType, PlainValidator(_value_type)]
PkwWords = Annotated[PkwSetting, PlainValidator(buses.pkw_setting)]
Name = Annotated[str, Field(pattern=_NAME, min_length=1, max_length=_NAME_MAX, strict=True)]


class Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _describe(value: object) -> str:
    """``auto`` or ``off`` (YAML reads a bare ``off`` as false, ``on`` as true)."""
    if value is False:
        return "off"
    if value is True:
        return "auto"
    if value in ("auto", "off"):
        return str(value)
    raise ValueError(f"must be auto or off, not {short(repr(value))}")


# Whether the drive's own description elements (AK 4) are read: auto, or off.
Describe = Annotated[str, PlainValidator(_describe)]
# Whether the alarm words and fault numbers a drive's catalog explains are polled even
# where the configuration does not poll them: auto, or off.
Alarms = Annotated[str, PlainValidator(_describe)]
# Whether the drive's own fault and alarm logs are read (where its catalog has one): auto,
# or off.
Events = Annotated[str, PlainValidator(_describe)]
# Whether the counters a drive keeps of its own life (operating hours, energy, power-ups)
# that its catalog marks are polled even where the configuration does not poll them: auto,
# or off.
Counters = Annotated[str, PlainValidator(_describe)]


class Settings(Model):
    """The sweep of a drive's settings: every ``every``, the parameters its catalog marks
    as settings (``catalog``) or those listed."""

    every: SettingsEvery = 3600.0
    parameters: Literal["catalog"] | list[Notation] = "catalog"


def _settings(value: object) -> Settings | str:
    """``off`` (YAML's bare off is false), or ``{every, parameters}``."""
    if value is False or value == "off":
        return "off"
    if isinstance(value, Settings):
        return value
    if not isinstance(value, dict):
        raise ValueError(f"must be off or {{every, parameters}}, not {short(repr(value))}")
    return Settings.model_validate(value)


# The sweep of a drive's settings, or ``off``.
SettingsField = Annotated[Settings | str, PlainValidator(_settings)]
