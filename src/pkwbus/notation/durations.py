"""Durations as people write them: ``250ms``, ``1s``, ``5m``, ``1h`` or plain seconds.

Every duration a user gives (configuration file, command line, simulator
options) has a kind, and each kind its range: the table below is the one
place that says which. A value outside it, negative or not finite is
refused with a message naming the range, never clamped and never used.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

__all__ = [
    "DP_SLOT_TIME",
    "DP_WATCHDOG",
    "EVENTS_EVERY",
    "HINT",
    "HISTORY_RETENTION",
    "INTER_CHAR_TIMEOUT",
    "JOB_DEADLINE",
    "MQTT_HEARTBEAT",
    "MQTT_OUTBOX_AGE",
    "PAUSE",
    "POLL_INTERVAL",
    "RANGES",
    "RESPONSE_DELAY",
    "RS485_DELAY",
    "SETTINGS_EVERY",
    "SIM_LAG",
    "SIM_LATE",
    "SIM_PORT_OUTAGE",
    "STANDBY_LEASE",
    "STATS_INTERVAL",
    "TELEGRAM_TIMEOUT",
    "DurationRange",
    "parse_duration",
]

_DURATION = re.compile(
    r"^\s*([-+]?(?:[0-9]{1,12}(?:\.[0-9]{0,12})?|\.[0-9]{1,12}))\s*(ms|s|min|m|h)?\s*$"
)
_UNITS: Final[Mapping[str | None, float]] = {
    "ms": 0.001,
    "s": 1.0,
    "m": 60.0,
    "min": 60.0,
    "h": 3600.0,
    None: 1.0,
}
HINT: Final = "write 250ms, 1s, 5m, 1h or plain seconds"


@dataclass(frozen=True, slots=True)
class DurationRange:
    """What a duration is for (``what``, with its article) and the seconds it may take.

    Both ends are included: a ``low`` of 0 allows 0; above it, 0 is refused.
    """

    what: str
    low: float
    high: float

    def __str__(self) -> str:
        return f"{_human(self.low)} to {_human(self.high)}"


# The ranges of every duration a user can give; README.md, "Configuration", lists them.
TELEGRAM_TIMEOUT: Final = DurationRange("a telegram timeout", 0.001, 10.0)
PAUSE: Final = DurationRange("a pause before a request", 0.0001, 1.0)
INTER_CHAR_TIMEOUT: Final = DurationRange("an inter-character timeout", 0.0001, 1.0)
RESPONSE_DELAY: Final = DurationRange("a response delay", 0.0, 10.0)
POLL_INTERVAL: Final = DurationRange("a poll interval", 0.001, 86400.0)
JOB_DEADLINE: Final = DurationRange("a job deadline", 0.001, 3600.0)
SIM_LAG: Final = DurationRange("a simulated PKW lag", 0.0, 3600.0)
SIM_LATE: Final = DurationRange("the delay of a late answer", 0.0, 3600.0)
SIM_PORT_OUTAGE: Final = DurationRange("a port outage", 0.0, 3600.0)
STATS_INTERVAL: Final = DurationRange("a stats interval", 0.01, 3600.0)
# The kernel caps the RTS delays of RS-485 mode at 100 ms (serial_rs485, RS485_MAX_RTS_DELAY).
RS485_DELAY: Final = DurationRange("an RS-485 RTS delay", 0.0, 0.1)
DP_SLOT_TIME: Final = DurationRange("a slot time", 0.0005, 1.0)
# Set_Prm's watchdog counts 10 ms ticks times two factors of at most 255 (EN 50170 vol. 2).
DP_WATCHDOG: Final = DurationRange("a watchdog", 0.01, 650.25)
EVENTS_EVERY: Final = DurationRange("a drive log's watch interval", 1.0, 3600.0)
HISTORY_RETENTION: Final = DurationRange("a retention", 3600.0, 87600 * 3600.0)  # 10 years
SETTINGS_EVERY: Final = DurationRange("a settings sweep interval", 1.0, 86400.0)
# etcd grants no lease under 1.5 s (its default election timeout); above a minute a dead
# master keeps its lines too long.
STANDBY_LEASE: Final = DurationRange("a standby lease", 2.0, 60.0)
MQTT_HEARTBEAT: Final = DurationRange("an MQTT heartbeat", 1.0, 86400.0)
MQTT_OUTBOX_AGE: Final = DurationRange("an MQTT outbox age", 60.0, 720 * 3600.0)  # 30 days

# Where each kind is given: the table of README.md, "Configuration", row by row.
RANGES: Final[tuple[tuple[str, DurationRange], ...]] = (
    ("line `timeout`, `--timeout`", TELEGRAM_TIMEOUT),
    ("line `pause`", PAUSE),
    ("line `inter_char_timeout`", INTER_CHAR_TIMEOUT),
    (
        "line `response_delay`, `sim://...&response_delay=`, `simulate --response-delay`",
        RESPONSE_DELAY,
    ),
    ("poll `every`", POLL_INTERVAL),
    ("`read`/`write --deadline`", JOB_DEADLINE),
    ("`simulate --lag` (as a duration)", SIM_LAG),
    ("`simulate --late-after`", SIM_LATE),
    ("`simulate --port-outage`", SIM_PORT_OUTAGE),
    ("`simulate --stats-interval`", STATS_INTERVAL),
    ("line `rs485` `delay_before_tx`, `delay_before_rx` (whole milliseconds)", RS485_DELAY),
    ("profibus line `slot_time`, `--slot-time`", DP_SLOT_TIME),
    ("profibus line `watchdog`", DP_WATCHDOG),
    ("line and drive `events_every`", EVENTS_EVERY),
    ("`history_retention`", HISTORY_RETENTION),
    ("line and drive `settings` `every`", SETTINGS_EVERY),
    ("`standby` `lease`", STANDBY_LEASE),
    ("`mqtt` `values` `heartbeat`", MQTT_HEARTBEAT),
    ("`mqtt` `outbox` `max_age`", MQTT_OUTBOX_AGE),
)


def _human(seconds: float) -> str:
    """``0.001`` as ``1 ms``, ``86400`` as ``24 h``."""
    if seconds == 0:
        return "0"
    for unit, size in (("h", 3600.0), ("min", 60.0), ("s", 1.0)):
        if seconds >= size and (seconds / size).is_integer():
            return f"{seconds / size:g} {unit}"
    if seconds >= 1:
        return f"{seconds:g} s"
    return f"{seconds * 1000:g} ms"


def _shown(value: object) -> str:
    """A scalar's repr (shortened); for anything else, what kind of thing it is."""
    if isinstance(value, list | tuple):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def parse_duration(
    value: object, within: DurationRange | None = None, *, allow_zero: bool = False
) -> float:
    """Seconds, within the range of its kind; ValueError with a plain message otherwise.

    Without ``within``: any finite duration above 0 (at least 0 with ``allow_zero``).
    """
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise ValueError(f"{_shown(value)} is not a duration: {HINT}")
    if isinstance(value, str):
        found = _DURATION.match(value)
        if found is None:
            raise ValueError(f"{_shown(value)} is not a duration: {HINT}")
        seconds = float(found[1]) * _UNITS[found[2]]
    else:
        try:
            seconds = float(value)
        except OverflowError:
            seconds = math.inf
    if not math.isfinite(seconds):
        raise ValueError(f"{_shown(value)} is not a finite duration: {HINT}")
    zero_ok = within.low == 0 if within is not None else allow_zero
    if seconds < 0 or (seconds == 0 and not zero_ok):
        floor = "0 or more" if zero_ok else "above 0"
        where = f": {within.what} is {within}" if within is not None else f": {HINT}"
        raise ValueError(f"{_shown(value)} is not a duration {floor}{where}")
    if within is None:
        return seconds
    if seconds > within.high:
        raise ValueError(f"{_shown(value)} is too long for {within.what} ({within})")
    if seconds < within.low:
        raise ValueError(f"{_shown(value)} is too short for {within.what} ({within})")
    return seconds
