"""PROFIdrive base mode parameter access (data record 47): request and response bytes."""

from __future__ import annotations

import struct

import pytest

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profidrive.drive import decode_request, encode_response
from pkwbus.protocol.profidrive.parameters import (
    MAX_PARAMETERS,
    MAX_RECORD,
    Attribute,
    Change,
    Format,
    ParameterAddress,
    ParameterError,
    ParameterRequest,
    RequestId,
    Values,
    decode_response,
)

# SINAMICS G120X operating instructions, "Parameter channel", example: change
# p1121 (ramp-down time) to 12.15 s. Reference 0x80, change, DO 1, one parameter,
# value attribute, one element, PNU 0x0461, subindex 0, float, one value.
G120X_CHANGE_P1121 = bytes.fromhex("80 02 01 01 10 01 04 61 00 00 08 01 41 42 66 66")


def test_the_g120x_change_of_p1121_encodes_byte_for_byte() -> None:
    request = ParameterRequest.change(
        0x80, 1, [Change(ParameterAddress(1121), Values(Format.FLOAT, (12.15,)))]
    )
    assert request.encode() == G120X_CHANGE_P1121


def test_the_g120x_change_of_p1121_decodes_as_the_manual_explains() -> None:
    request = decode_request(G120X_CHANGE_P1121)
    assert (request.reference, request.request_id, request.axis) == (0x80, RequestId.CHANGE, 1)
    assert request.addresses == (ParameterAddress(1121, 0, 1, Attribute.VALUE),)
    (values,) = request.changes
    assert values.format is Format.FLOAT
    assert values.values[0] == pytest.approx(12.15, abs=1e-6)


def test_a_change_done_is_the_head_alone() -> None:
    request = decode_request(G120X_CHANGE_P1121)
    response = decode_response(bytes.fromhex("80 02 01 01"), request)
    assert not response.failed
    assert response.results == (None,)


def test_a_failed_change_carries_its_error_number_in_words() -> None:
    request = decode_request(G120X_CHANGE_P1121)
    # response ID 0x82: format 0x44, one value, error 0x02 (limit exceeded)
    response = decode_response(bytes.fromhex("80 82 01 01 44 01 00 02"), request)
    assert response.failed
    (error,) = response.results
    assert isinstance(error, ParameterError)
    assert error.number == 2
    assert error.text == "Lower or upper value limit exceeded"


def test_a_read_of_three_parameters_and_its_response() -> None:
    addresses = [ParameterAddress(2), ParameterAddress(27), ParameterAddress(945, 1, 3)]
    request = ParameterRequest.read(7, 1, addresses)
    data = request.encode()
    head, body = data[:4], data[4:]
    assert head == bytes((7, 0x01, 1, 3))
    assert [struct.unpack_from(">BBHH", body, 6 * i) for i in range(3)] == [
        (0x10, 1, 2, 0), (0x10, 1, 27, 0), (0x10, 3, 945, 1)
    ]  # fmt: skip
    answer = (
        bytes((7, 0x81, 1, 3))
        + bytes((Format.U16, 1)) + (1).to_bytes(2, "big")
        + bytes((Format.FLOAT, 1)) + struct.pack(">f", 3.5)
        + bytes((Format.ERROR, 2)) + (3).to_bytes(2, "big") + (1).to_bytes(2, "big")
    )  # fmt: skip
    response = decode_response(answer, request)
    assert response.failed
    first, second, third = response.results
    assert first == Values(Format.U16, (1,))
    assert second == Values(Format.FLOAT, (3.5,))
    assert third == ParameterError(3, 1)
    assert str(third) == "error 0x03: Invalid subindex (additional value 1)"


def test_signed_and_byte_values_with_their_padding() -> None:
    request = ParameterRequest.read(1, 0, [ParameterAddress(10, 0, 3), ParameterAddress(11)])
    answer = bytes((1, 1, 0, 2, Format.I8, 3, 0xFF, 0x80, 0x7F, 0, Format.I32, 1)) + (-5).to_bytes(
        4, "big", signed=True
    )
    response = decode_response(answer, request)
    assert response.results == (Values(Format.I8, (-1, -128, 127)), Values(Format.I32, (-5,)))
    assert encode_response(request, response.results) == answer


@pytest.mark.parametrize(
    ("answer", "why"),
    [
        (bytes((9, 1, 1, 1, Format.U16, 1, 0, 1)), "another request"),
        (bytes((7, 2, 1, 1)), "response ID"),
        (bytes((7, 1, 0, 1, Format.U16, 1, 0, 1)), "axis"),
        (bytes((7, 1, 1, 2, Format.U16, 1, 0, 1)), "of 2 parameters"),
        (bytes((7, 1, 1, 1, Format.U16, 1, 0)), "cut short"),
        (bytes((7, 1, 1, 1, Format.U16, 1, 0, 1, 0)), "after the last"),
        (bytes((7, 1, 1, 1, 0x33, 1, 0, 1)), "format 0x33"),
        (bytes((7, 1, 1, 1, Format.U16, 2, 0, 1, 0, 2)), "2 values"),
        (bytes((7, 1, 1, 1, Format.ERROR, 1, 0, 1)), "does not match"),
        (bytes((7, 1, 1)), "at least 4"),
    ],
)
def test_a_response_that_is_not_the_answer_is_refused(answer: bytes, why: str) -> None:
    request = ParameterRequest.read(7, 1, [ParameterAddress(2)])
    with pytest.raises(RemoteProtocolError, match=why):
        decode_response(answer, request)


def test_a_request_that_cannot_be_sent_says_why() -> None:
    too_many = [ParameterAddress(n) for n in range(MAX_PARAMETERS + 1)]
    with pytest.raises(LocalProtocolError, match="40 parameters"):
        ParameterRequest.read(1, 1, too_many).encode()
    with pytest.raises(LocalProtocolError, match="reference 0"):
        ParameterRequest.read(0, 1, [ParameterAddress(2)]).encode()
    with pytest.raises(LocalProtocolError, match="does not fit"):
        ParameterRequest.change(
            1, 1, [Change(ParameterAddress(2), Values(Format.U16, (70000,)))]
        ).encode()
    with pytest.raises(LocalProtocolError, match="outside 0-65535"):
        ParameterAddress(70000).encode()


def test_thirty_nine_reads_fit_one_record() -> None:
    request = ParameterRequest.read(1, 1, [ParameterAddress(n) for n in range(MAX_PARAMETERS)])
    assert len(request.encode()) == 4 + 6 * MAX_PARAMETERS <= MAX_RECORD


def test_error_numbers_in_the_vendors_words() -> None:
    from pkwbus.protocol.profidrive.errors import error_text

    # SINAMICS CU240S Operating Instructions, table 6-25
    assert error_text(0x00) == "Illegal parameter number"
    assert error_text(0x16) == "Illegal parameter address"
    # Danfoss MG.33.C2.02, "Error codes for DP V1 parameter requests"
    assert error_text(0x66, "danfoss-pcv") == "Unknown service request"
    assert "manufacturer-specific error 102" in error_text(0x66, "profidrive")
    assert "not defined by PROFIdrive" in error_text(0x08)
