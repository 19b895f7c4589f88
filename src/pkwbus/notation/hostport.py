"""``HOST:PORT`` as users write it, in one place: the service's ``listen``, the
simulator's ``--listen`` and ``--stats-listen``, and the TCP port of a
``socket://`` or ``rfc2217://`` serial port.

A host is a host name, an IPv4 address or an IPv6 address in brackets
(``[::1]:9725``); the port is a whole number in the range the caller gives:
1-65535 where a port is connected to or served on a fixed port, 0-65535 where
0 means any free port.

:func:`parse_host_port` raises :class:`ValueError` with a one-line message
that shows the text as written; nothing else.
"""

from __future__ import annotations

import ipaddress
import re
from typing import Final

from pkwbus.notation.problems import short

__all__ = ["ANY_FREE_PORT", "MAX_TCP_PORT", "check_host", "parse_host_port"]

MAX_TCP_PORT: Final = 65535
ANY_FREE_PORT: Final = 0  # the lowest port where the system may choose one

_HOSTNAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,252}$")


def _example(scheme: str) -> str:
    return f"e.g. {scheme}127.0.0.1:9725 or {scheme}[::1]:9725"


def check_host(host: str) -> str:
    """``host`` when it is a host name, an IPv4 address or a bare IPv6 address."""
    if ":" in host:
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise ValueError(f"{host!r} is not an IPv6 address") from None
    elif not _HOSTNAME.match(host):
        raise ValueError(f"{host!r} is not a host name or address")
    return host


def parse_host_port(text: str, *, lowest_port: int, scheme: str = "") -> tuple[str, int]:
    """``[scheme]HOST:PORT`` or ``[scheme][IPv6]:PORT`` as (host, port).

    ``lowest_port`` is 1, or :data:`ANY_FREE_PORT` where 0 lets the system
    choose. ``scheme`` (``"tcp://"``) must begin ``text`` when given.
    """
    shown = short(text)
    written = f"{scheme}HOST:PORT ({_example(scheme)})"
    rest = text.strip()
    if scheme:
        if not rest.lower().startswith(scheme.lower()):
            raise ValueError(f"{shown} is not {written}")
        rest = rest[len(scheme) :]
    head, sep, port = rest.rpartition(":")
    if not sep or not head:
        raise ValueError(f"{shown} is not {written}")
    bracketed = head.startswith("[") and head.endswith("]")
    if ":" in head and not bracketed:
        raise ValueError(f"{shown}: write an IPv6 address in brackets, {_example(scheme)}")
    try:
        host = check_host(head[1:-1] if bracketed else head)
        if bracketed and ":" not in host:
            raise ValueError(f"{host!r} is not an IPv6 address")
    except ValueError as exc:
        raise ValueError(f"{shown}: {exc}") from None
    if not port.isdigit() or len(port) > 5 or not lowest_port <= int(port) <= MAX_TCP_PORT:
        free = " (0: any free port)" if lowest_port == ANY_FREE_PORT else ""
        raise ValueError(f"{shown}: the TCP port must be {lowest_port}-{MAX_TCP_PORT}{free}")
    return host, int(port)
