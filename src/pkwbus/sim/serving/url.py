"""``sim://PROTOCOL?drives=1,2,3&response_delay=3ms&refuse_descriptions=3&keypad_every=10m``:
a port that starts simulated drives (``refuse_descriptions``: drives that answer no
description element; ``keypad_every``: on average once per that time, one drive of the
line gets a setting changed at its keypad, with no bus write: :data:`KEYPAD_EVERY` says
the range).

:func:`parse_sim_port` raises ValueError with a plain message when the URL is malformed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final
from urllib.parse import parse_qsl, urlsplit

from pkwbus.notation import durations, limits
from pkwbus.notation.durations import DurationRange, parse_duration
from pkwbus.protocol.buses import Bus

__all__ = ["KEYPAD_EVERY", "SimPort", "parse_sim_port"]

#: The range of ``keypad_every``: from a second (a busy demo) to a week.
KEYPAD_EVERY: Final = DurationRange("a keypad change interval", 1.0, 7 * 86400.0)


@dataclass(frozen=True, slots=True)
class SimPort:
    """A ``sim://PROTOCOL?drives=1,2,3&response_delay=3ms`` port: start simulated drives.

    ``keypad_every``: seconds; on average once per that time one drive of the line gets
    a setting changed at its keypad (None: never).
    """

    protocol: Bus
    drives: tuple[int, ...]
    response_delay: float | None = None
    refuse_descriptions: tuple[int, ...] = ()
    keypad_every: float | None = None


def parse_sim_port(url: str) -> SimPort:
    """Parse a ``sim://`` port; ValueError with a plain message when it is malformed."""
    parts = urlsplit(url)
    if parts.scheme != "sim" or parts.path not in ("", "/") or parts.fragment:
        raise ValueError(f"{url!r} is not sim://fc?drives=1,2 or sim://uss?drives=...")
    try:
        protocol = Bus(parts.netloc.lower())
    except ValueError:
        raise ValueError(f"{url!r}: simulated protocol must be fc or uss") from None
    options = _sim_options(url, parts.query)
    if "drives" not in options:
        raise ValueError(f"{url!r}: list the simulated drives, e.g. ?drives=1,2,3")
    drives = _address_list(url, options["drives"])
    refusing: tuple[int, ...] = ()
    if "refuse_descriptions" in options:
        refusing = _address_list(url, options["refuse_descriptions"], "refuse_descriptions")
        if strangers := sorted(set(refusing) - set(drives)):
            raise ValueError(f"{url!r}: refuse_descriptions names {strangers}, not in drives")
    delay = _duration(url, options, "response_delay", durations.RESPONSE_DELAY)
    keypad = _duration(url, options, "keypad_every", KEYPAD_EVERY)
    return SimPort(protocol, drives, delay, refusing, keypad)


_OPTIONS = ("drives", "response_delay", "refuse_descriptions", "keypad_every")


def _duration(url: str, options: dict[str, str], key: str, within: DurationRange) -> float | None:
    """The duration of option ``key``, None when it is not given."""
    text = options.get(key)
    if text is None:
        return None
    try:
        return parse_duration(text, within)
    except ValueError as exc:
        raise ValueError(f"{url!r}: {key} {exc}") from None


def _sim_options(url: str, query: str) -> dict[str, str]:
    try:
        pairs = parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query))
    except ValueError:
        raise ValueError(f"{url!r}: options must be key=value&key=value") from None
    options: dict[str, str] = {}
    for key, value in pairs:
        if key not in _OPTIONS:
            known = ", ".join(_OPTIONS)
            raise ValueError(f"{url!r}: unknown option {key!r} (known: {known})")
        if key in options:
            raise ValueError(f"{url!r}: option {key!r} is given twice")
        options[key] = value
    return options


def _address_list(url: str, text: str, key: str = "drives") -> tuple[int, ...]:
    try:
        addresses = limits.parse_addresses(text, 0, limits.MAX_ADDRESS)
    except ValueError as exc:
        raise ValueError(f"{url!r}: {key} must be addresses like 1,2,5-7: {exc}") from None
    if not addresses:
        raise ValueError(f"{url!r}: {key} must be addresses like 1,2,5-7, not {text!r}")
    return tuple(addresses)
