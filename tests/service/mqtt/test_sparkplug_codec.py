"""The Sparkplug B codec against the specification's payload examples (Eclipse Sparkplug
3.0.0, "Payloads": NBIRTH, NCMD, NDEATH) and Cirrus Link's MQTT Engine NBIRTH example (a
negative Int32 with a Quality property). The expected bytes are built here, field by
field, from the numbers and wire types of the specification's ``Payload`` message, with a
varint of the test's own: never by the codec under test."""

from __future__ import annotations

import struct

import pytest

from pkwbus.service.mqtt.sparkplug.codec import (
    DataType,
    Metric,
    Payload,
    PropertyValue,
    SparkplugError,
    decode,
    encode,
)

TS = 1486144502122  # the specification's examples' timestamp


def varint(n: int) -> bytes:
    out = b""
    while n > 0x7F:
        out += bytes([n & 0x7F | 0x80])
        n >>= 7
    return out + bytes([n])


def key(number: int, wire: int) -> bytes:
    return bytes([number << 3 | wire])  # every field number here is below 16


def length(number: int, data: bytes) -> bytes:
    return key(number, 2) + varint(len(data)) + data


def test_the_varint_of_the_test_is_protobufs() -> None:
    # The protobuf encoding guide's own example: 150 is 96 01.
    assert varint(150) == b"\x96\x01"
    # TS in 7-bit groups, lowest first: 0x6a 0x72 0x75 0x28 0x20 0x2b, each but the last
    # with its high bit set.
    assert varint(TS) == bytes([0xEA, 0xF2, 0xF5, 0xA8, 0xA0, 0x2B])
    assert sum(g << 7 * i for i, g in enumerate([0x6A, 0x72, 0x75, 0x28, 0x20, 0x2B])) == TS


# NDEATH ("Payloads", NDEATH): {"timestamp": TS, "metrics": [{"name": "bdSeq",
# "timestamp": TS, "dataType": "UInt64", "value": 0}]}
NDEATH_METRIC = (
    length(1, b"bdSeq")  # name = 1
    + key(3, 0) + varint(TS)  # timestamp = 3
    + key(4, 0) + varint(8)  # datatype = 4: UInt64
    + key(11, 0) + varint(0)  # long_value = 11
)  # fmt: skip
NDEATH = key(1, 0) + varint(TS) + length(2, NDEATH_METRIC)

# NCMD ("Payloads", NCMD): Node Control/Rebirth, Boolean, true.
NCMD = (
    key(1, 0) + varint(TS)
    + length(2, length(1, b"Node Control/Rebirth") + key(3, 0) + varint(TS)
             + key(4, 0) + varint(11) + key(14, 0) + varint(1))  # boolean_value = 14
)  # fmt: skip

# NBIRTH ("Payloads", NBIRTH), three of its metrics: bdSeq Int64 0, Node Control/Rebirth
# Boolean false, Supply Voltage Float 12.1; seq 0.
NBIRTH = (
    key(1, 0) + varint(TS)
    + length(2, length(1, b"bdSeq") + key(3, 0) + varint(TS) + key(4, 0) + varint(4)
             + key(11, 0) + varint(0))
    + length(2, length(1, b"Node Control/Rebirth") + key(3, 0) + varint(TS)
             + key(4, 0) + varint(11) + key(14, 0) + varint(0))
    + length(2, length(1, b"Supply Voltage") + key(3, 0) + varint(TS) + key(4, 0) + varint(9)
             + key(12, 5) + struct.pack("<f", 12.1))  # float_value = 12, 32-bit
    + key(3, 0) + varint(0)  # seq = 3
)  # fmt: skip

# MQTT Engine's NBIRTH example: "Sine0", Int32, -49, properties {"Quality": Int32 192}.
# An Int32 goes in the uint32 int_value (10) as its two's complement.
SINE = (
    length(1, b"Sine0") + key(3, 0) + varint(1644444653413) + key(4, 0) + varint(3)
    + key(10, 0) + varint(0xFFFFFFCF)
    + length(9, length(1, b"Quality")  # PropertySet: keys = 1, values = 2
             + length(2, key(1, 0) + varint(3) + key(3, 0) + varint(192)))
)  # fmt: skip


def test_ndeath() -> None:
    payload = Payload(TS, [Metric("bdSeq", timestamp=TS, datatype=DataType.UINT64, value=0)])
    assert encode(payload) == NDEATH
    assert decode(NDEATH) == payload


def test_ncmd_rebirth() -> None:
    found = decode(NCMD)
    assert found.timestamp == TS and found.seq is None
    [metric] = found.metrics
    assert (metric.name, metric.datatype, metric.value) == ("Node Control/Rebirth", 11, True)
    assert encode(found) == NCMD


def test_nbirth() -> None:
    payload = Payload(
        TS,
        [
            Metric("bdSeq", timestamp=TS, datatype=DataType.INT64, value=0),
            Metric("Node Control/Rebirth", timestamp=TS, datatype=DataType.BOOLEAN, value=False),
            Metric("Supply Voltage", timestamp=TS, datatype=DataType.FLOAT, value=12.1),
        ],
        seq=0,
    )
    assert encode(payload) == NBIRTH
    found = decode(NBIRTH)
    assert found.seq == 0 and [m.name for m in found.metrics] == [m.name for m in payload.metrics]
    voltage = found.metrics[2].value
    assert isinstance(voltage, float) and voltage == pytest.approx(12.1, rel=1e-7)
    assert found.metrics[1].value is False


def test_a_negative_int32_and_a_property() -> None:
    metric = Metric(
        "Sine0",
        timestamp=1644444653413,
        datatype=DataType.INT32,
        value=-49,
        properties={"Quality": PropertyValue(DataType.INT32, 192)},
    )
    payload = Payload(metrics=[metric])
    assert encode(payload) == length(2, SINE)
    assert decode(length(2, SINE)) == payload


def test_aliases_and_null() -> None:
    data = length(2, key(2, 0) + varint(300) + key(7, 0) + varint(1))  # alias 300, is_null
    [metric] = decode(data).metrics
    assert metric.alias == 300 and metric.is_null and metric.value is None
    assert encode(Payload(metrics=[Metric(alias=300, is_null=True)])) == data


def test_unknown_fields_are_skipped() -> None:
    # A metadata (8) in the metric and an extension field (6) in the payload.
    data = NDEATH + length(6, b"\x08\x01")
    extra = length(2, length(8, length(1, b"text/plain")) + key(2, 0) + varint(5))
    assert decode(data) == decode(NDEATH)
    assert decode(extra).metrics[0].alias == 5


@pytest.mark.parametrize(
    "data",
    [NDEATH[:-1], NCMD[:5], b"\x0a\x10abc", b"\x07", b"\x00\x01", b"\x08" + b"\xff" * 11],
    ids=["cut_value", "cut_field", "past_end", "wire_7", "field_0", "long_varint"],
)
def test_what_is_not_a_payload_is_refused(data: bytes) -> None:
    with pytest.raises(SparkplugError):
        decode(data)


@pytest.mark.parametrize(
    ("datatype", "value"),
    [
        (DataType.INT8, 128),
        (DataType.UINT16, -1),
        (DataType.UINT32, 1 << 32),
        (DataType.INT32, 1.5),
        (DataType.BOOLEAN, 1),
        (DataType.STRING, 3),
        (DataType.FLOAT, 1e39),
    ],
)
def test_a_value_its_datatype_cannot_carry_is_refused(datatype: DataType, value: object) -> None:
    with pytest.raises(SparkplugError):
        encode(Payload(metrics=[Metric("x", datatype=datatype, value=value)]))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("datatype", "value"),
    [
        (DataType.INT8, -128),
        (DataType.INT16, -2),
        (DataType.INT64, -(1 << 63)),
        (DataType.UINT64, (1 << 64) - 1),
        (DataType.UINT32, 0xFFFFFFFF),
        (DataType.DOUBLE, -0.5),
        (DataType.STRING, "Hz"),
        (DataType.DATETIME, TS),
    ],
)
def test_each_datatype_comes_back(datatype: DataType, value: object) -> None:
    payload = Payload(metrics=[Metric("x", alias=2, datatype=datatype, value=value)])  # type: ignore[arg-type]
    assert decode(encode(payload)) == payload
