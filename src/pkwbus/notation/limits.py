"""The ranges of the whole numbers a user gives: command line, configuration, simulator.

Durations have their own table in :mod:`pkwbus.notation.durations`. Bus addresses and
PKW/PZD lengths depend on the protocol and dialect; they are checked where
the drive is built (:meth:`pkwbus.master.target.DriveTarget.create`), with
:data:`MAX_ADDRESS` only as the bound no protocol goes beyond.
"""

from __future__ import annotations

import re
from typing import Final

from pkwbus.notation.hostport import MAX_TCP_PORT, parse_host_port

__all__ = [
    "BAUDRATES",
    "MAX_ADDRESS",
    "MAX_AUDIT_LIMIT",
    "MAX_LAG_TELEGRAMS",
    "MAX_RETRIES",
    "MAX_TCP_PORT",
    "check_baudrate",
    "check_int",
    "check_port_url",
    "parse_addresses",
    "parse_int",
    "parse_size",
]

# The standard RS-485 rates FC and USS drives are set to, 1200 baud up to 187.5 kbaud.
BAUDRATES: Final = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 76800, 93750, 115200, 187500)
MAX_RETRIES: Final = 100  # repeats of one request after a missing or bad answer
MAX_ADDRESS: Final = 126  # the highest bus address of any protocol (FC 1-126, USS 0-30)
MAX_AUDIT_LIMIT: Final = 10_000  # audit entries one request shows, as GET /api/v1/audit
MAX_LAG_TELEGRAMS: Final = 1000  # simulated PKW lag, counted in telegrams


def check_int(value: int, low: int, high: int) -> int:
    """``value`` when it is ``low``-``high``; ValueError naming the range otherwise."""
    if not low <= value <= high:
        raise ValueError(f"{value} is outside {low}-{high}")
    return value


def parse_int(text: str, low: int, high: int) -> int:
    """The whole number written ``text``, ``low``-``high``; ValueError with a plain message."""
    try:
        value = int(text) if len(text) <= 40 else None
    except ValueError:
        value = None
    if value is None:
        shown = text if len(text) <= 40 else text[:37] + "..."
        raise ValueError(f"{shown!r} is not a whole number {low}-{high}")
    return check_int(value, low, high)


def parse_addresses(text: str, low: int, high: int) -> list[int]:
    """``1,2,5`` or ``1-3,7`` as the sorted addresses, each ``low``-``high``.

    Empty items are skipped (``""`` is no address). ValueError for an item that
    is not a number or a range, a range that runs backwards, or an address
    outside ``low``-``high`` (checked before any range is expanded).
    """
    found: set[int] = set()
    for part in filter(None, (p.strip() for p in text.split(","))):
        first, sep, last = (x.strip() for x in part.partition("-"))
        if not first.isdigit() or (sep and not last.isdigit()):
            raise ValueError(f"{part[:40]!r} is not an address or a range like 1-3")
        for address in (first, last or first):
            if len(address) > 3 or not low <= int(address) <= high:
                raise ValueError(f"address {address[:40]} is outside {low}-{high}")
        if int(first) > int(last or first):
            raise ValueError(f"address range {part} runs backwards")
        found.update(range(int(first), int(last or first) + 1))
    return sorted(found)


def check_baudrate(value: int) -> int:
    """``value`` when it is one of :data:`BAUDRATES`; ValueError listing them otherwise."""
    if value not in BAUDRATES:
        known = " ".join(str(b) for b in BAUDRATES)
        raise ValueError(f"{value} is not a supported baud rate ({known})")
    return value


def check_port_url(url: str) -> str:
    """A ``socket://`` or ``rfc2217://`` port needs HOST:PORT with a TCP port 1-65535
    (:func:`pkwbus.notation.hostport.parse_host_port`); ValueError otherwise.

    Other ports (device paths, ``loop://``, ...) pass unchanged.
    """
    scheme, sep, rest = url.partition("://")
    if not sep or scheme.lower() not in ("socket", "rfc2217"):
        return url
    address = rest.split("?", 1)[0].split("/", 1)[0]
    parse_host_port(f"{scheme}://{address}", lowest_port=1, scheme=f"{scheme}://")
    return url


_SIZE = re.compile(r"^\s*([0-9]{1,15})\s*(B|KiB|MiB|GiB|kB|MB|GB)?\s*$")
_SIZE_UNITS: Final = {None: 1, "B": 1, "kB": 1000, "MB": 1000**2, "GB": 1000**3,
                      "KiB": 1024, "MiB": 1024**2, "GiB": 1024**3}  # fmt: skip


def parse_size(value: object, low: int, high: int) -> int:
    """Bytes written ``64MiB``, ``500kB``, ``1GiB`` or a plain whole number, ``low``-``high``;
    ValueError with a plain message otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | str):
        raise ValueError(f"{str(value)[:40]!r} is not a size: write 64MiB, 500kB or bytes")
    if isinstance(value, int):
        size = value
    else:
        found = _SIZE.match(value)
        if found is None:
            raise ValueError(f"{value[:40]!r} is not a size: write 64MiB, 500kB or bytes")
        size = int(found[1]) * _SIZE_UNITS[found[2]]
    if not low <= size <= high:
        raise ValueError(f"{value!s:.40} is outside {low}-{high} bytes")
    return size
