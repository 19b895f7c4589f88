"""MSAC_C1 requests a master cannot send and answers that are not the answer
(pkwbus.protocol.profibus.dpv1.msac), and the transfer's misfed answers (dpv1.transfer).

``5F slot index length data`` is answered ``5F slot index length``; ``5E slot index
length`` is answered ``5E slot index length data`` (EN 50170 vol. 2 / IEC 61158-6-3,
"MSAC_C1 services"); slots 0-254, indices 0-255, at most 240 bytes.
"""

from __future__ import annotations

import pytest

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus.dpv1.msac import (
    C1Function,
    C1Request,
    Dpv1Setup,
    ReadDone,
    WriteDone,
    decode_c1,
    decode_c1_request,
    read_request,
    request_frame,
    write_request,
)
from pkwbus.protocol.profibus.dpv1.transfer import NO_DATA, C1Transfer, RecordFailed

# ABB FPBA-01 user's manual, example 3: the write of a request to slot 1 index 47.
ABB_WRITE_918 = bytes.fromhex("5F 01 2F 0A 09 01 01 01 10 00 03 96 00 00")


@pytest.mark.parametrize(
    ("slot", "index", "why"),
    [
        (255, 47, "slot 255 is outside 0-254"),
        (-1, 47, "slot -1"),
        (0, 256, "index 256 is outside 0-255"),
    ],
)
def test_a_record_no_slave_has(slot: int, index: int, why: str) -> None:
    with pytest.raises(LocalProtocolError, match=why):
        read_request(slot, index)
    with pytest.raises(LocalProtocolError, match=why):
        write_request(slot, index, b"\x01")


def test_the_last_slot_and_index() -> None:
    assert read_request(254, 255, 1) == bytes.fromhex("5E FE FF 01")


@pytest.mark.parametrize("length", [0, 241])
def test_a_read_of_no_bytes_or_more_than_240(length: int) -> None:
    with pytest.raises(LocalProtocolError, match=f"a read of {length} bytes \\(1-240\\)"):
        read_request(0, 47, length)


@pytest.mark.parametrize("length", [0, 241])
def test_a_write_of_no_bytes_or_more_than_240(length: int) -> None:
    with pytest.raises(LocalProtocolError, match=f"a write of {length} bytes \\(1-240\\)"):
        write_request(0, 47, bytes(length))


def test_a_write_of_240_bytes() -> None:
    assert write_request(0, 47, bytes(240))[:4] == bytes.fromhex("5F 00 2F F0")


@pytest.mark.parametrize(
    ("slave", "master", "why"),
    [(126, 2, "slave address 126 is outside 0-125"), (8, 126, "master address 126")],
)
def test_a_request_frame_to_or_from_no_station(slave: int, master: int, why: str) -> None:
    with pytest.raises(LocalProtocolError, match=why):
        request_frame(slave, master, read_request(0, 47), fcb=True, fcv=True)


def test_the_write_response_is_the_requests_head() -> None:
    assert decode_c1(ABB_WRITE_918[:4], C1Function.WRITE, 1, 47) == WriteDone(1, 47, 10)


@pytest.mark.parametrize(
    ("data", "function", "why"),
    [
        ("5E 01 2F", C1Function.READ, "an MSAC_C1 response of 3 bytes \\(at least 4\\)"),
        ("5F 01", C1Function.WRITE, "an MSAC_C1 response of 2 bytes"),
        ("5F 01 2F 0A 09", C1Function.WRITE, "a write response of 5 bytes \\(4\\)"),
        ("DF 80 B5", C1Function.WRITE, "a negative MSAC_C1 response of 3 bytes \\(4\\)"),
    ],
)
def test_an_answer_that_is_no_msac_c1_answer(data: str, function: C1Function, why: str) -> None:
    with pytest.raises(RemoteProtocolError, match=why):
        decode_c1(bytes.fromhex(data), function, 1, 47)


def test_requests_as_the_slave_receives_them() -> None:
    assert decode_c1_request(ABB_WRITE_918) == C1Request(
        C1Function.WRITE, 1, 47, 10, ABB_WRITE_918[4:]
    )
    assert decode_c1_request(bytes.fromhex("5E 00 2F F0")) == C1Request(C1Function.READ, 0, 47, 240)


@pytest.mark.parametrize(
    ("data", "why"),
    [
        ("5E 00 2F", "an MSAC_C1 request of 3 bytes \\(at least 4\\)"),
        ("17 00 2F F0", "MSAC_C1 function 0x17"),  # neither read (5E) nor write (5F)
        ("5F 01 2F 0A 09 01", "a write of 2 bytes, 10 said"),
        ("5E 00 2F F0 00", "a read request of 5 bytes \\(4\\)"),
    ],
)
def test_a_request_a_slave_cannot_read(data: str, why: str) -> None:
    with pytest.raises(RemoteProtocolError, match=why):
        decode_c1_request(bytes.fromhex(data))


def test_master_and_slave_agree_on_every_request_byte() -> None:
    for pdu in (read_request(3, 47, 17), write_request(3, 47, b"\x01\x02\x03")):
        request = decode_c1_request(pdu)
        encoded = (
            read_request(request.slot, request.index, request.length)
            if request.function is C1Function.READ
            else write_request(request.slot, request.index, request.data)
        )
        assert encoded == pdu


# ------------------------------------------------------------- the transfer


SETUP = Dpv1Setup(max_data=240, response_timeout=0.5)


@pytest.mark.parametrize(
    ("reading", "answer", "why"),
    [
        (False, ReadDone(1, 47, b"\x00"), "ReadDone answers a write"),
        (True, WriteDone(1, 47, 10), "WriteDone answers a read"),
    ],
)
def test_an_answer_to_the_other_function_ends_the_transfer(
    reading: bool, answer: ReadDone | WriteDone, why: str
) -> None:
    transfer = C1Transfer(1, 47, ABB_WRITE_918[4:], SETUP, now=0.0)
    if reading:
        assert transfer.feed(WriteDone(1, 47, 10), 0.01) is None
    end = transfer.feed(answer, 0.02)
    assert end == RecordFailed(why)
    assert transfer.end == end


def test_an_ended_transfer_takes_no_more_answers() -> None:
    transfer = C1Transfer(1, 47, ABB_WRITE_918[4:], SETUP, now=0.0)
    transfer.feed(ReadDone(1, 47, b""), 0.01)  # ends it
    with pytest.raises(LocalProtocolError, match="the transfer is over"):
        transfer.feed(NO_DATA, 0.02)
    with pytest.raises(LocalProtocolError, match="the transfer is over"):
        transfer.next_pdu()


def test_a_write_the_slave_is_never_ready_for_times_out() -> None:
    transfer = C1Transfer(1, 47, ABB_WRITE_918[4:], SETUP, now=0.0)
    assert transfer.feed(NO_DATA, 0.49) is None
    assert transfer.next_pdu() == ABB_WRITE_918  # the write again
    end = transfer.feed(NO_DATA, 0.5)
    assert isinstance(end, RecordFailed) and end.timed_out
    assert end.why == "the slave had no write ready within its response timeout (0.5 s)"
