"""The two kinds of protocol error, as in h11: ours and the peer's."""

from __future__ import annotations

from pkwbus.errors import PkwbusError

__all__ = ["LocalProtocolError", "ProtocolError", "RemoteProtocolError"]


class ProtocolError(PkwbusError):
    """Base of every error the protocol layer raises."""


class LocalProtocolError(ProtocolError, ValueError):
    """We were asked for something the protocol (or the dialect) cannot say."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something the protocol does not allow."""
