"""PROFIdrive base mode parameter access: the request and response of data record 47.

The layout is PROFIdrive's (SINAMICS G120 CU240B-2/CU240E-2 and G120X
operating instructions, "Parameter channel" / "data set 47"; Danfoss VLT
PROFIBUS DP MCA 101 manual, "PCA parameter access"), big-endian throughout:

- **Request**: reference (1-255, mirrored in the response), request ID (0x01
  request parameter, 0x02 change parameter), axis or drive object (DO-ID:
  SINAMICS 1, Danfoss 0), number of parameters (1-39); then per parameter an
  address: attribute (0x10 value, 0x20 description, 0x30 text), number of
  elements (1 for a single value, up to 234 of an array), parameter number
  (U16), subindex (U16, the first array element). A change then carries, per
  parameter, its values: format, number of values, the values.
- **Response**: the same head, the ID 0x81 or 0x82 when a parameter failed;
  then per parameter (read) its values, or (change) nothing but, for a failed
  one, its error: format 0x44, number of values, the error number and an
  additional value where the drive gives one. Values of one byte are padded
  with 0x00 to an even length. A value of a time type (TimeOfDay or
  TimeDifference with date: 6 bytes, ms then days) is one number of its bytes.

The worked example, the change of p1121 to 12.15 in the SINAMICS G120X
operating instructions ("Parameter channel", example), is
``80 02 01 01 10 01 04 61 00 00 08 01 41 42 66 66``.

Pure: bytes in, objects out. :class:`LocalProtocolError` for a request that
cannot be built, :class:`RemoteProtocolError` for a response that does not
decode.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profidrive.errors import error_text

__all__ = [
    "AXES",
    "MAX_PARAMETERS",
    "MAX_RECORD",
    "RECORD",
    "Attribute",
    "Change",
    "Format",
    "ParameterAddress",
    "ParameterError",
    "ParameterRequest",
    "ParameterResponse",
    "RequestId",
    "Result",
    "Value",
    "Values",
    "decode_response",
    "decode_values",
]

RECORD: Final = 47  # the data record (index) of parameter access, in slot 0
# The axis (drive object) of each DP dialect that has parameter access: SINAMICS DO-ID 1
# ("at G120 always = 1", G120X operating instructions, table 6-14), Danfoss axis 0
# (MCA 101 programming manual, 5.2.13 "Set the axis attribute to 0"). Hitachi's SJ-PB
# documents the PKW channel only.
AXES: Final = {"profidrive": 1, "danfoss-pcv": 0}
MAX_RECORD: Final = 240  # bytes of one request or response (PROFIdrive base mode)
MAX_PARAMETERS: Final = 39  # parameters in one request
MAX_ELEMENTS: Final = 234
_HEAD = 4


class RequestId(enum.IntEnum):
    READ = 0x01  # "request parameter"
    CHANGE = 0x02  # "change parameter"
    # Danfoss: "Change parameter non-volatile (data is stored in non-volatile memory)",
    # VLT PROFIBUS DP MCA 101 programming manual, 5.2.11.
    CHANGE_NON_VOLATILE = 0x42


class Attribute(enum.IntEnum):
    VALUE = 0x10
    DESCRIPTION = 0x20
    TEXT = 0x30


class Format(enum.IntEnum):
    """The data type of a parameter's values in a request or response."""

    BOOLEAN = 0x01
    I8 = 0x02
    I16 = 0x03
    I32 = 0x04
    U8 = 0x05
    U16 = 0x06
    U32 = 0x07
    FLOAT = 0x08
    VISIBLE_STRING = 0x09
    OCTET_STRING = 0x0A
    # The time types, each one number: ms (U32) then days (U16) since 1984-01-01; ms then
    # days; ms (Siemens PROFIdrive application example PDRV V4.2, data types 12, 53, 54).
    TIME_OF_DAY_WITH_DATE = 0x0C
    TIME_DIFFERENCE_WITH_DATE = 0x35
    TIME_DIFFERENCE_WITHOUT_DATE = 0x36
    ZERO = 0x40  # no values: the change was done
    BYTE = 0x41
    WORD = 0x42
    DOUBLE_WORD = 0x43
    ERROR = 0x44

    @property
    def size(self) -> int:
        """Bytes of one value (0: none)."""
        return _SIZES[self]


_SIZES: Final = {
    Format.BOOLEAN: 1, Format.I8: 1, Format.U8: 1, Format.BYTE: 1,
    Format.VISIBLE_STRING: 1, Format.OCTET_STRING: 1,
    Format.I16: 2, Format.U16: 2, Format.WORD: 2, Format.ERROR: 2,
    Format.I32: 4, Format.U32: 4, Format.DOUBLE_WORD: 4, Format.FLOAT: 4,
    Format.TIME_DIFFERENCE_WITHOUT_DATE: 4,
    Format.TIME_OF_DAY_WITH_DATE: 6, Format.TIME_DIFFERENCE_WITH_DATE: 6,
    Format.ZERO: 0,
}  # fmt: skip
_SIGNED: Final = frozenset({Format.I8, Format.I16, Format.I32})
_TEXTS: Final = frozenset({Format.VISIBLE_STRING, Format.OCTET_STRING})

Value = int | float | bytes


@dataclass(frozen=True, slots=True)
class ParameterAddress:
    """Which parameter, which of its elements, which attribute."""

    pnu: int
    subindex: int = 0
    elements: int = 1
    attribute: Attribute = Attribute.VALUE

    def encode(self) -> bytes:
        if not 0 <= self.pnu <= 0xFFFF:
            raise LocalProtocolError(f"parameter number {self.pnu} is outside 0-65535")
        if not 0 <= self.subindex <= 0xFFFF:
            raise LocalProtocolError(f"subindex {self.subindex} is outside 0-65535")
        if not 0 <= self.elements <= MAX_ELEMENTS:
            raise LocalProtocolError(f"{self.elements} elements (at most {MAX_ELEMENTS})")
        return struct.pack(">BBHH", self.attribute, self.elements, self.pnu, self.subindex)


@dataclass(frozen=True, slots=True)
class Values:
    """A parameter's values in a response (or a change's request), by their format."""

    format: Format
    values: tuple[Value, ...]

    def encode(self) -> bytes:
        fmt = self.format
        if fmt is Format.ZERO:
            return bytes((fmt, 0))
        if fmt in _TEXTS:
            (text,) = self.values
            if not isinstance(text, bytes):
                raise LocalProtocolError(f"a {fmt.name} value is bytes, not {text!r}")
            return _pad(bytes((fmt, len(text))) + text)
        body = b"".join(_pack(fmt, v) for v in self.values)
        if len(self.values) > 0xFF:
            raise LocalProtocolError(f"{len(self.values)} values (at most 255)")
        return _pad(bytes((fmt, len(self.values))) + body)


@dataclass(frozen=True, slots=True)
class ParameterError:
    """A parameter the drive could not read or change: its PROFIdrive error number."""

    number: int
    extra: int | None = None  # the additional value some errors carry (a subindex, say)

    @property
    def text(self) -> str:
        return error_text(self.number)

    def __str__(self) -> str:
        more = "" if self.extra is None else f" (additional value {self.extra})"
        return f"error {self.number:#04x}: {self.text}{more}"

    def encode(self) -> bytes:
        words = (self.number,) if self.extra is None else (self.number, self.extra)
        return bytes((Format.ERROR, len(words))) + b"".join(w.to_bytes(2, "big") for w in words)


Result = Values | ParameterError | None  # None: a change done (no values back)


@dataclass(frozen=True, slots=True)
class Change:
    """One parameter of a change request: where, and the values to write."""

    address: ParameterAddress
    values: Values


@dataclass(frozen=True, slots=True)
class ParameterRequest:
    reference: int
    request_id: RequestId
    axis: int
    addresses: tuple[ParameterAddress, ...]
    changes: tuple[Values, ...] = ()  # a change's values, one per address

    @classmethod
    def read(
        cls, reference: int, axis: int, addresses: Sequence[ParameterAddress]
    ) -> ParameterRequest:
        return cls(reference, RequestId.READ, axis, tuple(addresses))

    @classmethod
    def change(cls, reference: int, axis: int, changes: Sequence[Change]) -> ParameterRequest:
        return cls(
            reference, RequestId.CHANGE, axis, tuple(c.address for c in changes),
            tuple(c.values for c in changes),
        )  # fmt: skip

    def encode(self) -> bytes:
        if not 1 <= self.reference <= 0xFF:
            raise LocalProtocolError(f"request reference {self.reference} is outside 1-255")
        if not 0 <= self.axis <= 0xFF:
            raise LocalProtocolError(f"axis {self.axis} is not a byte")
        if not 1 <= len(self.addresses) <= MAX_PARAMETERS:
            raise LocalProtocolError(
                f"{len(self.addresses)} parameters in one request (1-{MAX_PARAMETERS})"
            )
        if self.request_id is not RequestId.READ:
            if len(self.changes) != len(self.addresses):
                raise LocalProtocolError("a change needs values for every parameter")
        elif self.changes:
            raise LocalProtocolError("a read carries no values")
        head = bytes((self.reference, self.request_id, self.axis, len(self.addresses)))
        body = b"".join(a.encode() for a in self.addresses)
        body += b"".join(v.encode() for v in self.changes)
        data = head + body
        if len(data) > MAX_RECORD:
            raise LocalProtocolError(f"a request of {len(data)} bytes (at most {MAX_RECORD})")
        return data


@dataclass(frozen=True, slots=True)
class ParameterResponse:
    reference: int
    request_id: RequestId
    failed: bool  # response ID 0x81/0x82: at least one parameter failed
    axis: int
    results: tuple[Result, ...]


def decode_response(data: bytes, request: ParameterRequest) -> ParameterResponse:
    """The response to ``request``; RemoteProtocolError when it is not that response."""
    if len(data) < _HEAD:
        raise RemoteProtocolError(f"a parameter response of {len(data)} bytes (at least 4)")
    reference, rid, axis, count = data[:_HEAD]
    failed = bool(rid & 0x80)
    if reference != request.reference:
        raise RemoteProtocolError(
            f"response reference {reference} answers another request ({request.reference})"
        )
    if rid & 0x7F != request.request_id:
        raise RemoteProtocolError(f"response ID {rid:#04x} to request ID {request.request_id:#04x}")
    if axis != request.axis:
        raise RemoteProtocolError(f"response for axis {axis}, request for {request.axis}")
    if count != len(request.addresses):
        raise RemoteProtocolError(
            f"a response of {count} parameters to a request of {len(request.addresses)}"
        )
    pos = _HEAD
    results: list[Result] = []
    change = request.request_id is not RequestId.READ
    for address in request.addresses:
        if change and not failed:
            results.append(None)
            continue
        if change and pos >= len(data):
            raise RemoteProtocolError("a failed change's response is cut short")
        result, pos = decode_values(data, pos, address)
        if not change and isinstance(result, Values) and result.format is Format.ZERO:
            raise RemoteProtocolError(f"a read of parameter {address.pnu} answered with no value")
        if change and isinstance(result, Values):
            if result.format is not Format.ZERO:
                raise RemoteProtocolError(f"a change answered with {result.format.name} values")
            result = None
        results.append(result)
    if pos != len(data):
        raise RemoteProtocolError(f"{len(data) - pos} bytes after the last parameter's values")
    if failed != any(isinstance(r, ParameterError) for r in results):
        raise RemoteProtocolError(f"response ID {rid:#04x} does not match its parameters' errors")
    return ParameterResponse(reference, RequestId(rid & 0x7F), failed, axis, tuple(results))


def decode_values(data: bytes, pos: int, address: ParameterAddress) -> tuple[Result, int]:
    if pos + 2 > len(data):
        raise RemoteProtocolError(f"the response ends before parameter {address.pnu}'s values")
    try:
        fmt = Format(data[pos])
    except ValueError:
        raise RemoteProtocolError(f"format {data[pos]:#04x} of parameter {address.pnu}") from None
    count = data[pos + 1]
    pos += 2
    size = fmt.size * count
    end = pos + size
    if end > len(data):
        raise RemoteProtocolError(f"parameter {address.pnu}'s {count} values are cut short")
    raw = data[pos:end]
    if fmt is Format.ERROR:
        if count not in (1, 2):
            raise RemoteProtocolError(f"an error of {count} values for parameter {address.pnu}")
        words = [int.from_bytes(raw[i : i + 2], "big") for i in range(0, size, 2)]
        return ParameterError(words[0], words[1] if count == 2 else None), end
    if size % 2:
        end += 1  # one byte of padding
        if end > len(data):
            raise RemoteProtocolError(f"parameter {address.pnu}'s values lack their padding")
    if fmt in _TEXTS:
        return Values(fmt, (bytes(raw),)), end
    asked = max(address.elements, 1)
    if fmt is not Format.ZERO and address.attribute is Attribute.VALUE and count != asked:
        raise RemoteProtocolError(
            f"{count} values of parameter {address.pnu}, {address.elements} asked for"
        )
    values = tuple(_unpack(fmt, raw[i : i + fmt.size]) for i in range(0, size, fmt.size or 1))
    return Values(fmt, values), end


def _unpack(fmt: Format, raw: bytes) -> Value:
    if fmt is Format.FLOAT:
        return float(struct.unpack(">f", raw)[0])
    return int.from_bytes(raw, "big", signed=fmt in _SIGNED)


def _pack(fmt: Format, value: Value) -> bytes:
    if fmt is Format.FLOAT:
        if isinstance(value, bytes):
            raise LocalProtocolError(f"a float value is a number, not {value!r}")
        return struct.pack(">f", value)
    if not isinstance(value, int) or isinstance(value, bool):
        raise LocalProtocolError(f"a {fmt.name} value is a whole number, not {value!r}")
    size = fmt.size
    signed = fmt in _SIGNED
    try:
        return value.to_bytes(size, "big", signed=signed)
    except OverflowError:
        raise LocalProtocolError(f"{value} does not fit a {fmt.name} value") from None


def _pad(data: bytes) -> bytes:
    return data + b"\x00" if len(data) % 2 else data
