"""The drive's side of PROFIdrive parameter access (data record 47): a request as a drive
receives it, and its response as the drive sends it. For the simulator and the tests;
the layout is :mod:`pkwbus.protocol.profidrive.parameters`'s."""

from __future__ import annotations

import struct
from collections.abc import Sequence

from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profidrive.parameters import (
    MAX_PARAMETERS,
    Attribute,
    Format,
    ParameterAddress,
    ParameterError,
    ParameterRequest,
    RequestId,
    Result,
    Values,
    decode_values,
)

__all__ = ["decode_request", "encode_response"]

_HEAD = 4
_ADDRESS = 6


def decode_request(data: bytes) -> ParameterRequest:
    """A request as a drive receives it (the simulator's side, and tests)."""
    if len(data) < _HEAD:
        raise RemoteProtocolError(f"a parameter request of {len(data)} bytes (at least 4)")
    reference, rid, axis, count = data[:_HEAD]
    try:
        request_id = RequestId(rid)
    except ValueError:
        raise RemoteProtocolError(f"request ID {rid:#04x}") from None
    if not 1 <= count <= MAX_PARAMETERS:
        raise RemoteProtocolError(f"{count} parameters in one request")
    pos = _HEAD
    addresses: list[ParameterAddress] = []
    for _ in range(count):
        if pos + _ADDRESS > len(data):
            raise RemoteProtocolError("a parameter request is cut short")
        attribute, elements, pnu, subindex = struct.unpack_from(">BBHH", data, pos)
        try:
            addresses.append(ParameterAddress(pnu, subindex, elements, Attribute(attribute)))
        except ValueError:
            raise RemoteProtocolError(f"attribute {attribute:#04x}") from None
        pos += _ADDRESS
    changes: list[Values] = []
    if request_id is not RequestId.READ:
        for address in addresses:
            result, pos = decode_values(data, pos, address)
            if not isinstance(result, Values):
                raise RemoteProtocolError(f"a change of parameter {address.pnu} with an error")
            changes.append(result)
    if pos != len(data):
        raise RemoteProtocolError(f"{len(data) - pos} bytes after the request's last parameter")
    return ParameterRequest(reference, request_id, axis, tuple(addresses), tuple(changes))


def encode_response(request: ParameterRequest, results: Sequence[Result]) -> bytes:
    """The drive's response to ``request`` (the simulator's side, and tests)."""
    failed = any(isinstance(r, ParameterError) for r in results)
    rid = request.request_id | (0x80 if failed else 0)
    head = bytes((request.reference, rid, request.axis, len(results)))
    parts: list[bytes] = []
    for result in results:
        if isinstance(result, ParameterError | Values):
            parts.append(result.encode())
        elif failed:
            parts.append(Values(Format.ZERO, ()).encode())
    return head + b"".join(parts)
