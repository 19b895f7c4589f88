"""DP-V1 class 1 services (MSAC_C1) and the record transfer, on vendors' byte examples."""

from __future__ import annotations

import pytest

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp.services import Parameters
from pkwbus.protocol.profibus.dpv1.msac import (
    C1_SAP,
    C1Error,
    C1Function,
    Dpv1Setup,
    Dpv1Status,
    ReadDone,
    WriteDone,
    decode_c1,
    decode_c1_request,
    encode_c1_error,
    read_request,
    request_frame,
    with_dpv1,
    write_request,
)
from pkwbus.protocol.profibus.dpv1.transfer import NO_DATA, C1Transfer, RecordFailed, RecordRead
from pkwbus.protocol.profidrive.parameters import (
    Format,
    ParameterAddress,
    ParameterRequest,
    Values,
    decode_response,
)

# ABB FPBA-01 PROFIBUS DP adapter module User's manual, "Communication protocol",
# example 3 (reading PROFIdrive parameter 918, the station number): the data units
# of the DP-V1 write request and of the read response (slot 1, index 47).
ABB_WRITE_918 = bytes.fromhex("5F 01 2F 0A 09 01 01 01 10 00 03 96 00 00")
ABB_READ_RESPONSE_918 = bytes.fromhex("5E 01 2F 08 09 01 01 01 42 01 00 03")
# Example 1b: three parameters (12.04, 20.08, 30.19) in one request.
ABB_WRITE_THREE = bytes.fromhex(
    "5F 01 2F 16 06 01 01 03 10 01 00 0C 00 04 10 01 00 14 00 08 10 01 00 1E 00 13"
)
# SINAMICS (Industrial Security Configuration Manual A5E36912609A, tables ):
# read r0002 from DO 1, and the response, Integer16 31.
SINAMICS_READ_R0002 = bytes.fromhex("80 01 01 01 10 01 00 02 00 00")
SINAMICS_RESPONSE_R0002 = bytes.fromhex("80 01 01 01 03 01 00 1F")


def test_the_abb_read_of_parameter_918_byte_for_byte() -> None:
    request = ParameterRequest.read(9, 1, [ParameterAddress(918, 0, 0)])
    assert write_request(1, 47, request.encode()) == ABB_WRITE_918
    answer = decode_c1(ABB_READ_RESPONSE_918, C1Function.READ, 1, 47)
    assert isinstance(answer, ReadDone)
    response = decode_response(answer.data, request)
    assert response.results == (Values(Format.WORD, (3,)),)


def test_the_abb_read_of_three_parameters_byte_for_byte() -> None:
    addresses = [ParameterAddress(0x0C, 4), ParameterAddress(0x14, 8), ParameterAddress(0x1E, 0x13)]
    request = ParameterRequest.read(6, 1, addresses)
    assert write_request(1, 47, request.encode()) == ABB_WRITE_THREE


def test_the_sinamics_read_of_r0002() -> None:
    request = ParameterRequest.read(0x80, 1, [ParameterAddress(2)])
    assert request.encode() == SINAMICS_READ_R0002
    assert decode_response(SINAMICS_RESPONSE_R0002, request).results == (Values(Format.I16, (31,)),)


def test_requests_and_their_frame() -> None:
    assert read_request(0, 47) == bytes((0x5E, 0, 47, 240))
    frame = request_frame(5, 2, read_request(0, 47), fcb=True, fcv=True)
    assert (frame.dsap, frame.ssap) == (C1_SAP, C1_SAP) == (51, 51)
    assert frame.control.function is fdl.Function.SRD_HIGH
    assert fdl.decode(fdl.encode(frame)) == frame
    assert decode_c1_request(ABB_WRITE_918).data == ABB_WRITE_918[4:]


@pytest.mark.parametrize(
    ("data", "function", "why"),
    [
        (bytes.fromhex("5E 00 2F 02 01"), C1Function.READ, "1 bytes, 2 said"),
        (bytes.fromhex("5E 01 2F 00"), C1Function.READ, "slot 1"),
        (bytes.fromhex("5F 00 2F 02"), C1Function.READ, "0x5f answers 0x5e"),
        (bytes.fromhex("DE 80 B5"), C1Function.READ, "3 bytes"),
        (b"", C1Function.WRITE, "without data"),
    ],
)
def test_answers_that_are_not_the_answer(data: bytes, function: C1Function, why: str) -> None:
    with pytest.raises(RemoteProtocolError, match=why):
        decode_c1(data, function, 0, 47)


def test_a_negative_answer_and_state_conflict() -> None:
    answer = decode_c1(bytes.fromhex("DE 80 B5 00"), C1Function.READ, 0, 47)
    assert isinstance(answer, C1Error) and answer.not_ready
    other = decode_c1(encode_c1_error(C1Function.WRITE, 0xB0), C1Function.WRITE, 0, 47)
    assert isinstance(other, C1Error) and not other.not_ready


def test_dpv1_on_in_the_first_user_parameter_byte() -> None:
    assert with_dpv1(b"") == bytes((0x80, 0, 0))
    assert with_dpv1(bytes((0x04, 0, 0, 7, 8))) == bytes((0x84, 0, 0, 7, 8))  # the GSD's kept
    assert Dpv1Status.decode(with_dpv1(b"\x01\x02")) == Dpv1Status(True, False)
    assert Dpv1Status.decode(b"\x00\x00\x00") is None
    assert len(Parameters(0x1234, user_prm=with_dpv1(b"")).encode()) == 10


SETUP = Dpv1Setup(max_data=240, response_timeout=0.5)


def test_a_transfer_writes_then_reads_until_the_response_is_there() -> None:
    transfer = C1Transfer(0, 47, SINAMICS_READ_R0002, SETUP, now=0.0)
    assert transfer.next_pdu() == write_request(0, 47, SINAMICS_READ_R0002)
    assert transfer.feed(NO_DATA, 0.01) is None  # not ready for the write: again
    assert transfer.next_pdu()[0] == C1Function.WRITE
    assert transfer.feed(WriteDone(0, 47, len(SINAMICS_READ_R0002)), 0.02) is None
    assert transfer.next_pdu() == read_request(0, 47, 240)
    not_ready = C1Error(C1Function.READ, 0x80, 0xB5, 0)
    assert transfer.feed(not_ready, 0.1) is None
    assert transfer.feed(NO_DATA, 0.2) is None
    end = transfer.feed(ReadDone(0, 47, SINAMICS_RESPONSE_R0002), 0.3)
    assert end == RecordRead(SINAMICS_RESPONSE_R0002, 3)


def test_a_transfer_gives_up_after_the_response_timeout() -> None:
    transfer = C1Transfer(0, 47, SINAMICS_READ_R0002, SETUP, now=0.0)
    transfer.feed(WriteDone(0, 47, 10), 1.0)
    not_ready = C1Error(C1Function.READ, 0x80, 0xB5, 0)
    assert transfer.feed(not_ready, 1.49) is None
    end = transfer.feed(not_ready, 1.5)
    assert isinstance(end, RecordFailed) and end.timed_out
    with pytest.raises(LocalProtocolError):
        transfer.next_pdu()


def test_a_refused_write_ends_the_transfer_with_its_reason() -> None:
    transfer = C1Transfer(0, 47, SINAMICS_READ_R0002, SETUP, now=0.0)
    error = C1Error(C1Function.WRITE, 0x80, 0xB0, 0)
    end = transfer.feed(error, 0.1)
    assert isinstance(end, RecordFailed) and end.error == error and not end.timed_out


def test_a_record_larger_than_the_slave_takes_is_refused() -> None:
    with pytest.raises(LocalProtocolError, match="at most 20"):
        C1Transfer(0, 47, bytes(21), Dpv1Setup(max_data=20), now=0.0)


@pytest.mark.parametrize(
    ("code1", "words"),
    [
        (0xB5, "Access, State Conflict"),
        (0xB0, "Access, Invalid Index"),
        (0xA9, "Application, Feature Not Supported"),
        (0xC2, "Resource, Busy"),
        (0xBE, "Access, code 14 (user-specific or reserved)"),
        (0xD3, "error class 13 (user-specific), code 3"),
    ],
)
def test_every_error_code_in_words(code1: int, words: str) -> None:
    # Beckhoff EL6731 "DPV1 Error Codes"; ABB FPBA-01 manual, table 10.
    error = C1Error(C1Function.READ, 0x80, code1, 0)
    assert error.text == words
    assert str(error) == f"DP-V1 read refused: {words}"


def test_a_non_dpv1_error_decode_is_named() -> None:
    assert C1Error(C1Function.WRITE, 0xFE, 1, 2).text.startswith("FMS, error codes 0x01 0x02")
