"""The drive's side of data record 47 (pkwbus.protocol.profidrive.drive): a request as a
drive receives it, and its response as the drive sends it."""

from __future__ import annotations

import pytest

from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profidrive.drive import decode_request, encode_response
from pkwbus.protocol.profidrive.parameters import (
    Change,
    Format,
    ParameterAddress,
    ParameterError,
    ParameterRequest,
    RequestId,
    Values,
    decode_response,
)

# ABB FPBA-01 user's manual, "Communication protocol", example 1b: a read of three
# parameters (12.04, 20.08, 30.19) in one request, reference 6, axis 1.
ABB_READ_THREE = bytes.fromhex("06 01 01 03 10 01 00 0C 00 04 10 01 00 14 00 08 10 01 00 1E 00 13")


def test_the_abb_read_of_three_parameters_as_the_drive_receives_it() -> None:
    request = decode_request(ABB_READ_THREE)
    assert (request.reference, request.request_id, request.axis) == (6, RequestId.READ, 1)
    assert request.addresses == (
        ParameterAddress(12, 4),
        ParameterAddress(20, 8),
        ParameterAddress(30, 19),
    )
    assert request.changes == ()


def test_the_danfoss_change_non_volatile_is_a_request_a_drive_knows() -> None:
    # VLT PROFIBUS DP MCA 101 programming manual, 5.2.11: request ID 0x42, "change
    # parameter non-volatile"; a word value 0x0003 for parameter 302, axis 0.
    data = bytes.fromhex("01 42 00 01 10 01 01 2E 00 00 42 01 00 03")
    request = decode_request(data)
    assert request.request_id is RequestId.CHANGE_NON_VOLATILE
    assert request.changes == (Values(Format.WORD, (3,)),)


@pytest.mark.parametrize(
    ("data", "why"),
    [
        ("01 01 01", "a parameter request of 3 bytes \\(at least 4\\)"),
        ("01 03 01 01 10 01 00 02 00 00", "request ID 0x03"),
        ("01 81 01 01 10 01 00 02 00 00", "request ID 0x81"),  # a response ID
        ("01 01 01 00", "0 parameters in one request"),
        ("01 01 01 28" + " 10 01 00 02 00 00" * 40, "40 parameters in one request"),
        ("01 01 01 02 10 01 00 02 00 00 10 01", "a parameter request is cut short"),
        ("01 01 01 01 40 01 00 02 00 00", "attribute 0x40"),
        ("01 02 01 01 10 01 00 02 00 00 44 01 00 02", "a change of parameter 2 with an error"),
        ("01 02 01 01 10 01 00 02 00 00 06 01 00", "parameter 2's 1 values are cut short"),
        ("01 01 01 01 10 01 00 02 00 00 00", "1 bytes after the request's last parameter"),
        ("01 02 01 01 10 01 00 02 00 00 06 01 00 07 00 00", "2 bytes after the request's"),
    ],
)
def test_a_request_a_drive_cannot_read_is_the_masters_error(data: str, why: str) -> None:
    with pytest.raises(RemoteProtocolError, match=why):
        decode_request(bytes.fromhex(data))


def test_every_request_the_master_encodes_the_drive_decodes() -> None:
    change = ParameterRequest.change(
        0x80, 1, [Change(ParameterAddress(1121), Values(Format.FLOAT, (12.5,)))]
    )
    assert decode_request(change.encode()) == change
    read = ParameterRequest.read(3, 0, [ParameterAddress(945, 1, 8), ParameterAddress(2)])
    assert decode_request(read.encode()) == read


def test_a_failed_change_of_two_answers_zero_for_the_one_done() -> None:
    # A response with ID 0x82 carries an entry for every parameter of the change:
    # format 0x40 "zero" (no values) for the one done, format 0x44 and its error
    # number for the one refused (here 0x02, value limit exceeded).
    request = ParameterRequest.change(
        5,
        1,
        [
            Change(ParameterAddress(1082), Values(Format.FLOAT, (1500.0,))),
            Change(ParameterAddress(1120), Values(Format.FLOAT, (-1.0,))),
        ],
    )
    data = encode_response(request, [None, ParameterError(0x02)])
    assert data == bytes.fromhex("05 82 01 02 40 00 44 01 00 02")
    response = decode_response(data, request)
    assert response.failed
    assert response.results == (None, ParameterError(0x02))


def test_a_change_done_is_the_head_alone() -> None:
    request = ParameterRequest.change(
        5, 1, [Change(ParameterAddress(1082), Values(Format.FLOAT, (1500.0,)))]
    )
    assert encode_response(request, [None]) == bytes.fromhex("05 02 01 01")


def test_an_error_with_its_additional_value() -> None:
    request = ParameterRequest.read(9, 1, [ParameterAddress(945, 20)])
    # error 0x03 "Invalid subindex", additional value 20
    data = encode_response(request, [ParameterError(0x03, 20)])
    assert data == bytes.fromhex("09 81 01 01 44 02 00 03 00 14")
    assert decode_response(data, request).results == (ParameterError(3, 20),)
