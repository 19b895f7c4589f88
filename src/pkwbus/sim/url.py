"""``sim://PROTOCOL?drives=1,2,3&response_delay=3ms``: a port that starts simulated drives.

:func:`parse_sim_port` raises ValueError with a plain message when the URL is malformed.
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import parse_qsl, urlsplit

from pkwbus import durations, limits
from pkwbus.durations import parse_duration
from pkwbus.protocol.telegram import Protocol

__all__ = ["SimPort", "parse_sim_port"]


@dataclass(frozen=True, slots=True)
class SimPort:
    """A ``sim://PROTOCOL?drives=1,2,3&response_delay=3ms`` port: start simulated drives."""

    protocol: Protocol
    drives: tuple[int, ...]
    response_delay: float | None = None


def parse_sim_port(url: str) -> SimPort:
    """Parse a ``sim://`` port; ValueError with a plain message when it is malformed."""
    parts = urlsplit(url)
    if parts.scheme != "sim" or parts.path not in ("", "/") or parts.fragment:
        raise ValueError(f"{url!r} is not sim://fc?drives=1,2 or sim://uss?drives=...")
    try:
        protocol = Protocol(parts.netloc.lower())
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
    try:
        addresses = limits.parse_addresses(text, 0, limits.MAX_ADDRESS)
    except ValueError as exc:
        raise ValueError(f"{url!r}: drives must be addresses like 1,2,5-7: {exc}") from None
    if not addresses:
        raise ValueError(f"{url!r}: drives must be addresses like 1,2,5-7, not {text!r}")
    return tuple(addresses)
