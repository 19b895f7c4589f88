"""The Sparkplug B payload (Eclipse Sparkplug 3.0.0, "Payloads": the ``Payload`` protobuf
message), encoded and decoded by hand on the protobuf wire format: no protobuf runtime
and no generated code.

What is covered: ``Payload`` (timestamp 1, metrics 2, seq 3, uuid 4, body 5) and its
``Metric`` (name 1, alias 2, timestamp 3, datatype 4, is_historical 5, is_transient 6,
is_null 7, properties 9, and the scalar values: int_value 10, long_value 11,
float_value 12, double_value 13, boolean_value 14, string_value 15, bytes_value 16),
with a ``PropertySet`` (keys 1, values 2) of scalar ``PropertyValue`` s (type 1,
is_null 2, values 3-8). Metadata, data sets, templates and extensions are skipped when
decoded and never encoded: pkwbus has none to send and reads only commands.

The specification's datatypes put Int8, Int16 and Int32 in the 32-bit ``int_value``
and Int64 in the 64-bit ``long_value``, a negative number as its two's complement;
:func:`decode` gives them back signed by the metric's datatype. Raises
:class:`SparkplugError` for bytes that are not such a payload, or a value that does not
fit its datatype.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field

from pkwbus.errors import PkwbusError

__all__ = [
    "DataType",
    "Metric",
    "MetricValue",
    "Payload",
    "PropertyValue",
    "SparkplugError",
    "decode",
    "encode",
]

MetricValue = int | float | bool | str | bytes


class SparkplugError(PkwbusError):
    """Bytes that are not a Sparkplug B payload, or a value its datatype cannot carry."""


class DataType(enum.IntEnum):
    """The specification's datatypes ("Payloads", DataType), the scalar ones."""

    UNKNOWN = 0
    INT8 = 1
    INT16 = 2
    INT32 = 3
    INT64 = 4
    UINT8 = 5
    UINT16 = 6
    UINT32 = 7
    UINT64 = 8
    FLOAT = 9
    DOUBLE = 10
    BOOLEAN = 11
    STRING = 12
    DATETIME = 13
    TEXT = 14
    UUID = 15
    BYTES = 17
    FILE = 18


# The value field of each datatype: in a Metric (10-16), in a PropertyValue (3-8).
_INT32 = {DataType.INT8, DataType.INT16, DataType.INT32, DataType.UINT8, DataType.UINT16,
          DataType.UINT32}  # fmt: skip
_INT64 = {DataType.INT64, DataType.UINT64, DataType.DATETIME}
_STRING = {DataType.STRING, DataType.TEXT, DataType.UUID}
_BITS = {DataType.INT8: 8, DataType.INT16: 16, DataType.INT32: 32, DataType.INT64: 64,
         DataType.UINT8: 8, DataType.UINT16: 16, DataType.UINT32: 32, DataType.UINT64: 64,
         DataType.DATETIME: 64}  # fmt: skip
_SIGNED = {DataType.INT8, DataType.INT16, DataType.INT32, DataType.INT64}
VARINT, I64, LEN, I32 = 0, 1, 2, 5  # protobuf wire types


@dataclass
class PropertyValue:
    type: int
    value: MetricValue | None = None  # None: is_null


@dataclass
class Metric:
    name: str | None = None
    alias: int | None = None
    timestamp: int | None = None
    datatype: int | None = None
    value: MetricValue | None = None  # None with is_null, or a DATA metric without one
    is_null: bool = False
    is_historical: bool = False
    is_transient: bool = False
    properties: dict[str, PropertyValue] = field(default_factory=dict)


@dataclass
class Payload:
    timestamp: int | None = None
    metrics: list[Metric] = field(default_factory=list)
    seq: int | None = None
    uuid: str | None = None
    body: bytes | None = None


# ------------------------------------------------------------------ encoding


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        byte = n & 0x7F
        n >>= 7
        if n:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _tag(number: int, wire: int) -> bytes:
    return _varint(number << 3 | wire)


def _uint(number: int, n: int) -> bytes:
    return _tag(number, VARINT) + _varint(n)


def _len(number: int, data: bytes) -> bytes:
    return _tag(number, LEN) + _varint(len(data)) + data


def _scalar(first: int, datatype: int, value: MetricValue) -> bytes:
    """``value`` in its datatype's field; ``first``: the int_value field's number (the
    others follow it in the specification's order)."""
    try:
        kind = DataType(datatype)
    except ValueError:
        raise SparkplugError(f"datatype {datatype} is not one pkwbus encodes") from None
    if kind in _INT32 or kind in _INT64:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SparkplugError(f"a {kind.name} takes a whole number, not {value!r}")
        bits = _BITS[kind]
        low, high = (0, (1 << bits) - 1)
        if kind in _SIGNED:
            low, high = -(1 << bits - 1), (1 << bits - 1) - 1
        if not low <= value <= high:
            raise SparkplugError(f"{value} does not fit a {kind.name}")
        if kind in _INT32:
            return _uint(first, value & 0xFFFFFFFF)
        return _uint(first + 1, value & 0xFFFFFFFFFFFFFFFF)
    if kind is DataType.FLOAT or kind is DataType.DOUBLE:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise SparkplugError(f"a {kind.name} takes a number, not {value!r}")
        if kind is DataType.FLOAT:
            try:
                return _tag(first + 2, I32) + struct.pack("<f", value)
            except OverflowError:
                raise SparkplugError(f"{value} does not fit a Float") from None
        return _tag(first + 3, I64) + struct.pack("<d", value)
    if kind is DataType.BOOLEAN:
        if not isinstance(value, bool):
            raise SparkplugError(f"a Boolean takes true or false, not {value!r}")
        return _uint(first + 4, int(value))
    if kind in _STRING:
        if not isinstance(value, str):
            raise SparkplugError(f"a {kind.name} takes a string, not {value!r}")
        return _len(first + 5, value.encode())
    if kind in (DataType.BYTES, DataType.FILE) and isinstance(value, bytes) and first == 10:
        return _len(16, value)
    raise SparkplugError(f"a {kind.name} value cannot be encoded here")


def _property_set(properties: dict[str, PropertyValue]) -> bytes:
    out = bytearray()
    for key in properties:
        out += _len(1, key.encode())
    for prop in properties.values():
        body = _uint(1, prop.type)
        body += _uint(2, 1) if prop.value is None else _scalar(3, prop.type, prop.value)
        out += _len(2, body)
    return bytes(out)


def _metric(metric: Metric, born: Mapping[int, int]) -> bytes:
    out = bytearray()
    if metric.name is not None:
        out += _len(1, metric.name.encode())
    if metric.alias is not None:
        out += _uint(2, metric.alias)
    if metric.timestamp is not None:
        out += _uint(3, metric.timestamp)
    if metric.datatype is not None:
        out += _uint(4, metric.datatype)
    for number, flag in ((5, metric.is_historical), (6, metric.is_transient)):
        if flag:
            out += _uint(number, 1)
    if metric.is_null or metric.value is None:
        if metric.is_null:
            out += _uint(7, 1)
    else:
        datatype = metric.datatype
        if datatype is None and metric.alias is not None:
            datatype = born.get(metric.alias)
        if datatype is None:
            raise SparkplugError(f"metric {metric.name or metric.alias}: a value needs a datatype")
        out += _scalar(10, datatype, metric.value)
    if metric.properties:
        out += _len(9, _property_set(metric.properties))
    return bytes(out)


def encode(payload: Payload, born: Mapping[int, int] | None = None) -> bytes:
    """The payload's bytes, fields in their numbers' order. ``born``: the datatypes of
    the aliases a birth announced, for the values of metrics that name none (DATA)."""
    out = bytearray()
    if payload.timestamp is not None:
        out += _uint(1, payload.timestamp)
    for metric in payload.metrics:
        out += _len(2, _metric(metric, born or {}))
    if payload.seq is not None:
        out += _uint(3, payload.seq)
    if payload.uuid is not None:
        out += _len(4, payload.uuid.encode())
    if payload.body is not None:
        out += _len(5, payload.body)
    return bytes(out)


# ------------------------------------------------------------------ decoding


def _fields(data: bytes) -> list[tuple[int, int, int | bytes]]:
    """(field number, wire type, value) of each field: a number for VARINT, I64 and I32
    (their little-endian bytes for the fixed ones), the bytes for LEN."""
    found: list[tuple[int, int, int | bytes]] = []
    i, end = 0, len(data)
    while i < end:
        key, i = _read_varint(data, i)
        number, wire = key >> 3, key & 7
        if number == 0:
            raise SparkplugError("not a Sparkplug B payload: field number 0")
        if wire == VARINT:
            value, i = _read_varint(data, i)
            found.append((number, wire, value))
        elif wire in (I64, I32):
            width = 8 if wire == I64 else 4
            if i + width > end:
                raise SparkplugError("not a Sparkplug B payload: it ends inside a number")
            found.append((number, wire, data[i : i + width]))
            i += width
        elif wire == LEN:
            length, i = _read_varint(data, i)
            if i + length > end:
                raise SparkplugError("not a Sparkplug B payload: a field runs past its end")
            found.append((number, wire, data[i : i + length]))
            i += length
        else:
            raise SparkplugError(f"not a Sparkplug B payload: wire type {wire}")
    return found


def _read_varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if i >= len(data) or shift > 63:
            raise SparkplugError("not a Sparkplug B payload: a number is cut short")
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, i


def _text(value: int | bytes) -> str:
    if not isinstance(value, bytes):
        raise SparkplugError("not a Sparkplug B payload: a number where text belongs")
    try:
        return value.decode()
    except UnicodeDecodeError:
        raise SparkplugError("not a Sparkplug B payload: text that is not UTF-8") from None


def _number(value: int | bytes) -> int:
    if not isinstance(value, int):
        raise SparkplugError("not a Sparkplug B payload: text where a number belongs")
    return value


def _value(offset: int, datatype: int | None, wire: int, raw: int | bytes) -> MetricValue:
    """The value of field ``offset`` after int_value (0: int_value ... 6: bytes_value)."""
    if offset in (0, 1):
        n = _number(raw)
        kind = _datatype(datatype)
        bits = 32 if offset == 0 else 64
        if kind in _SIGNED and n >= 1 << (bits - 1):
            n -= 1 << bits
        return n
    if offset == 2 and wire == I32 and isinstance(raw, bytes):
        return float(struct.unpack("<f", raw)[0])
    if offset == 3 and wire == I64 and isinstance(raw, bytes):
        return float(struct.unpack("<d", raw)[0])
    if offset == 4:
        return bool(_number(raw))
    if offset == 5:
        return _text(raw)
    if offset == 6 and isinstance(raw, bytes):
        return raw
    raise SparkplugError("not a Sparkplug B payload: a value of the wrong wire type")


def _datatype(datatype: int | None) -> DataType | None:
    try:
        return DataType(datatype) if datatype is not None else None
    except ValueError:
        return None


def _decode_properties(data: bytes) -> dict[str, PropertyValue]:
    keys: list[str] = []
    values: list[PropertyValue] = []
    for number, _wire, raw in _fields(data):
        if number == 1:
            keys.append(_text(raw))
        elif number == 2 and isinstance(raw, bytes):
            prop = PropertyValue(0)
            for n, w, r in _fields(raw):
                if n == 1:
                    prop.type = _number(r)
                elif 3 <= n <= 8:
                    prop.value = _value(n - 3, prop.type, w, r)
            values.append(prop)
    if len(keys) != len(values):
        raise SparkplugError("not a Sparkplug B payload: a property set's keys and values differ")
    return dict(zip(keys, values, strict=True))


def _decode_metric(data: bytes) -> Metric:
    metric = Metric()
    held: tuple[int, int, int | bytes] | None = None
    for number, wire, raw in _fields(data):
        if number == 1:
            metric.name = _text(raw)
        elif number == 2:
            metric.alias = _number(raw)
        elif number == 3:
            metric.timestamp = _number(raw)
        elif number == 4:
            metric.datatype = _number(raw)
        elif number in (5, 6, 7):
            flag = bool(_number(raw))
            if number == 5:
                metric.is_historical = flag
            elif number == 6:
                metric.is_transient = flag
            else:
                metric.is_null = flag
        elif number == 9 and isinstance(raw, bytes):
            metric.properties = _decode_properties(raw)
        elif 10 <= number <= 16:
            held = (number, wire, raw)  # decoded once the datatype is known
    if held is not None and not metric.is_null:
        metric.value = _value(held[0] - 10, metric.datatype, held[1], held[2])
    return metric


def decode(data: bytes) -> Payload:
    """The payload in ``data`` (unknown fields skipped)."""
    payload = Payload()
    for number, _wire, raw in _fields(data):
        if number == 1:
            payload.timestamp = _number(raw)
        elif number == 2 and isinstance(raw, bytes):
            payload.metrics.append(_decode_metric(raw))
        elif number == 3:
            payload.seq = _number(raw)
        elif number == 4:
            payload.uuid = _text(raw)
        elif number == 5 and isinstance(raw, bytes):
            payload.body = raw
    return payload
