"""PKW requests as PROFIdrive parameter requests (data record 47), pure.

A job stays in PKW terms everywhere above the wire (a poll's read, a job's
change, a description element); here each becomes one parameter of a base mode
request (:mod:`pkwbus.protocol.profidrive.parameters`): a value read or change of
attribute 0x10, a description element of attribute 0x20 (the element as the
subindex). A change carries its value in the parameter's own format (word or
double word where the type is not known: "Bytes, words and double words are
also possible as a substitute", SINAMICS field description of the parameter
request). A change goes to RAM ("change parameter"; SINAMICS G120X operating
instructions: "A save operation is needed in order to transfer the modified
data to the non-volatile memory"): a change to RAM and EEPROM is refused with
that reason. (Danfoss's "change parameter non-volatile", request ID 0x42 of
the MCA 101 programming manual 5.2.11, has no PKW request of its dialect to
come from.)
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.protocol.pkw.fields import Width
from pkwbus.protocol.profidrive import parameters as profidrive
from pkwbus.protocol.profidrive.parameters import (
    Attribute,
    Format,
    ParameterAddress,
    ParameterRequest,
    RequestId,
    Values,
)
from pkwbus.protocol.values.types import ValueType

__all__ = ["FORMATS", "RecordItem", "carried", "fits", "record_request"]

_READS = frozenset({Command.READ, Command.READ_ARRAY})
_EEPROM = frozenset(
    {
        Command.WRITE_WORD_EEPROM,
        Command.WRITE_DWORD_EEPROM,
        Command.WRITE_ARRAY_WORD_EEPROM,
        Command.WRITE_ARRAY_DWORD_EEPROM,
    }
)
FORMATS = {
    ValueType.U16: Format.U16,
    ValueType.I16: Format.I16,
    ValueType.U32: Format.U32,
    ValueType.I32: Format.I32,
    ValueType.F32: Format.FLOAT,
}
# The largest answer one value read may bring: format, count, four bytes.
_VALUE_ANSWER = 6


@dataclass(frozen=True, slots=True)
class RecordItem:
    """One PKW job's request, and the value type it is known by (None: not known)."""

    request: pkw.PkwRequest
    vtype: ValueType | None = None


def fits(count: int, max_data: int = profidrive.MAX_RECORD) -> bool:
    """Whether ``count`` value reads fit one request and its response: 240 bytes each, or
    the slave's ``C1_Max_Data_Len`` where it takes less."""
    if count > profidrive.MAX_PARAMETERS:
        return False
    return 4 + _VALUE_ANSWER * count <= min(max_data, profidrive.MAX_RECORD)


def carried(request: pkw.PkwRequest) -> str:
    """Why ``request`` does not travel in data record 47 here (empty: it does)."""
    try:
        _address(request)
    except LocalProtocolError as exc:
        return str(exc)
    return "texts do not travel in data record 47 here" if request.text else ""


def record_request(
    items: Sequence[RecordItem], *, reference: int, axis: int, dialect: str
) -> ParameterRequest:
    """The parameter request that carries ``items``: reads together, a change alone.
    LocalProtocolError for what data record 47 does not carry here."""
    if not items:
        raise LocalProtocolError("a parameter request of no parameters")
    writes = [item.request.is_write for item in items]
    if any(writes) and len(items) > 1:
        raise LocalProtocolError("a change goes alone in its request")
    if any(item.request.text for item in items):
        raise LocalProtocolError("texts do not travel in data record 47 here")
    addresses = [_address(item.request) for item in items]
    if not writes[0]:
        return ParameterRequest.read(reference, axis, addresses)
    if items[0].request.command in _EEPROM:
        raise LocalProtocolError(
            "a change in data record 47 goes to RAM only: write to RAM, then save as the"
            " drive's manual says"
        )
    change = RequestId.CHANGE
    return ParameterRequest(reference, change, axis, (addresses[0],), (_values(items[0]),))


def _address(request: pkw.PkwRequest) -> ParameterAddress:
    command = request.command
    if command in _READS or request.is_write:
        return ParameterAddress(request.pnu, request.subindex)
    if command is Command.READ_DESCRIPTION:
        return ParameterAddress(request.pnu, request.subindex, 1, Attribute.DESCRIPTION)
    raise LocalProtocolError(f"a {command.value} request does not travel in data record 47")


def _values(item: RecordItem) -> Values:
    """A change's value in the parameter's own format, a word or double word where its
    type is not known."""
    request = item.request
    raw = request.value
    fmt = FORMATS.get(item.vtype) if item.vtype is not None else None
    if fmt is None:
        return Values(Format.WORD if request.width is Width.WORD else Format.DOUBLE_WORD, (raw,))
    if fmt is Format.FLOAT:
        return Values(fmt, (struct.unpack(">f", raw.to_bytes(4, "big"))[0],))
    bits = 8 * fmt.size
    signed = fmt in (Format.I16, Format.I32) and raw >= 1 << (bits - 1)
    return Values(fmt, (raw - (1 << bits) if signed else raw,))
