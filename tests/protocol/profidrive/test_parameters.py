"""PROFIdrive parameter requests and responses (pkwbus.protocol.profidrive.parameters): what
a request cannot say, what a response must not say, texts, byte padding."""

from __future__ import annotations

import pytest

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profidrive.parameters import (
    MAX_RECORD,
    Attribute,
    Change,
    Format,
    ParameterAddress,
    ParameterRequest,
    RequestId,
    Value,
    Values,
    decode_response,
)


@pytest.mark.parametrize(
    ("address", "why"),
    [
        (ParameterAddress(2, 0x10000), "subindex 65536 is outside 0-65535"),
        (ParameterAddress(2, -1), "subindex -1 is outside 0-65535"),
        (ParameterAddress(945, 0, 235), "235 elements \\(at most 234\\)"),
    ],
)
def test_an_address_the_request_cannot_carry(address: ParameterAddress, why: str) -> None:
    with pytest.raises(LocalProtocolError, match=why):
        address.encode()


def test_the_largest_address() -> None:
    address = ParameterAddress(0xFFFF, 0xFFFF, 234, Attribute.TEXT)
    assert address.encode() == bytes.fromhex("30 EA FF FF FF FF")


@pytest.mark.parametrize(
    ("values", "data"),
    [
        (Values(Format.ZERO, ()), "40 00"),  # a change done: no values
        (Values(Format.U8, (1, 2, 3)), "05 03 01 02 03 00"),  # an odd byte count is padded
        (Values(Format.I8, (-1, 2)), "02 02 FF 02"),  # an even one is not
        (Values(Format.VISIBLE_STRING, (b"pump",)), "09 04 70 75 6D 70"),
        (Values(Format.OCTET_STRING, (b"\x01\x02\x03",)), "0A 03 01 02 03 00"),
        (Values(Format.I32, (-2,)), "04 01 FF FF FF FE"),
    ],
)
def test_values_byte_for_byte(values: Values, data: str) -> None:
    assert values.encode() == bytes.fromhex(data)


@pytest.mark.parametrize(
    ("values", "why"),
    [
        # a str where the layout takes bytes: the guard for an untyped caller
        (Values(Format.VISIBLE_STRING, ("pump",)), "a VISIBLE_STRING value is bytes"),  # type: ignore[arg-type]
        (Values(Format.FLOAT, (b"\x00\x00\x00\x00",)), "a float value is a number"),
        (Values(Format.U16, (1.5,)), "a U16 value is a whole number, not 1.5"),
        (Values(Format.U16, (True,)), "a U16 value is a whole number, not True"),
        (Values(Format.I16, (b"\x00\x01",)), "a I16 value is a whole number"),
        (Values(Format.U8, (0,) * 256), "256 values \\(at most 255\\)"),
        (Values(Format.I8, (128,)), "128 does not fit a I8 value"),
    ],
)
def test_values_a_request_cannot_carry(values: Values, why: str) -> None:
    with pytest.raises(LocalProtocolError, match=why):
        values.encode()


def _change(values: Values, address: ParameterAddress | None = None) -> ParameterRequest:
    return ParameterRequest.change(1, 1, [Change(address or ParameterAddress(2), values)])


def test_a_request_that_cannot_be_sent_says_why() -> None:
    address = ParameterAddress(2)
    with pytest.raises(LocalProtocolError, match="axis 256 is not a byte"):
        ParameterRequest.read(1, 256, [address]).encode()
    with pytest.raises(LocalProtocolError, match="a change needs values for every parameter"):
        ParameterRequest(1, RequestId.CHANGE, 1, (address, ParameterAddress(3)), ()).encode()
    with pytest.raises(LocalProtocolError, match="a read carries no values"):
        ParameterRequest(1, RequestId.READ, 1, (address,), (Values(Format.U16, (1,)),)).encode()
    # 60 double words of one array: 4 + 6 + 2 + 240 = 252 bytes, more than a record holds
    big = _change(Values(Format.U32, (0,) * 60), ParameterAddress(945, 0, 60))
    with pytest.raises(LocalProtocolError, match=f"a request of 252 bytes \\(at most {MAX_RECORD}"):
        big.encode()


def test_a_change_that_just_fits_the_record() -> None:
    # 4 + 6 + 2 + 4 x 57 = 240 bytes
    fits = _change(Values(Format.U32, (0,) * 57), ParameterAddress(945, 0, 57))
    assert len(fits.encode()) == MAX_RECORD


def test_a_text_read_answers_its_characters() -> None:
    request = ParameterRequest.read(4, 1, [ParameterAddress(2, 0, 1, Attribute.TEXT)])
    answer = bytes.fromhex("04 01 01 01 09 05") + b"Ready" + b"\x00"  # padded to even
    response = decode_response(answer, request)
    assert response.results == (Values(Format.VISIBLE_STRING, (b"Ready",)),)


@pytest.mark.parametrize(
    ("answer", "why"),
    [
        ("07 01 01 01", "the response ends before parameter 2's values"),
        ("07 01 01 01 06", "the response ends before parameter 2's values"),
        ("07 01 01 01 40 00", "a read of parameter 2 answered with no value"),
        ("07 81 01 01 44 03 00 01 00 02 00 03", "an error of 3 values for parameter 2"),
        ("07 81 01 01 44 00", "an error of 0 values for parameter 2"),
        ("07 01 01 01 05 01 2A", "parameter 2's values lack their padding"),
    ],
)
def test_a_read_response_that_does_not_decode(answer: str, why: str) -> None:
    request = ParameterRequest.read(7, 1, [ParameterAddress(2)])
    with pytest.raises(RemoteProtocolError, match=why):
        decode_response(bytes.fromhex(answer), request)


@pytest.mark.parametrize(
    ("answer", "why"),
    [
        # ID 0x82 but only the first parameter's entry
        ("07 82 01 02 44 01 00 02", "a failed change's response is cut short"),
        ("07 82 01 02 06 01 00 01 44 01 00 02", "a change answered with U16 values"),
        # ID 0x02 (done) with values after the head
        ("07 02 01 02 40 00 40 00", "4 bytes after the last parameter's values"),
        # ID 0x82 (failed) without an error among the parameters
        ("07 82 01 02 40 00 40 00", "response ID 0x82 does not match"),
    ],
)
def test_a_change_response_that_does_not_decode(answer: str, why: str) -> None:
    value: tuple[Value, ...] = (1,)
    request = ParameterRequest.change(
        7,
        1,
        [
            Change(ParameterAddress(2), Values(Format.U16, value)),
            Change(ParameterAddress(3), Values(Format.U16, value)),
        ],
    )
    with pytest.raises(RemoteProtocolError, match=why):
        decode_response(bytes.fromhex(answer), request)
