"""The root of pkwbus's own exceptions.

Every exception pkwbus raises on purpose - a bad configuration line, a port
that cannot be opened, a telegram that breaks the protocol, a command's
failure - is a :class:`PkwbusError`, with a message written for the people
who run the service: where something else escapes, it is a bug. A caller that
must not stop (a line, the service) tells the two apart by it.
"""

from __future__ import annotations

__all__ = ["PkwbusError"]


class PkwbusError(Exception):
    """An error pkwbus raises on purpose, its message meant for people."""
