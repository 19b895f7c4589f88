"""An answer decoded once while it stays the same: the serial carrier's decoded PKW answers
and the snapshot writer's decoded values give what decoding afresh gives, and decode
anew what changed (the answer, the notation, the drive)."""

from __future__ import annotations

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.carriers.serial import _KEPT_ANSWERS, SerialCarrier
from pkwbus.master.decoded import DecodedValues, job_result
from pkwbus.master.planning.outcomes import Answered, TimedOut
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.fields import Width
from pkwbus.protocol.serial.telegram import encode_block
from pkwbus.protocol.values.types import Scaling, ValueType

FC = DriveTarget.create("fc", 3)


def answer_data(target: DriveTarget, pnu: int, raw: int, status: int = 0x0607) -> bytes:
    """An FC drive's answer to a read of ``pnu``: its value as a double word, the status
    word and a main actual value beside it."""
    response = pkw.ValueResponse(2, pnu, 0, raw, Width.DWORD)
    block = pkw.encode_response(response, target.dialect, target.ind_layout, 4)
    return encode_block(block, (status, 0x1000))


def test_the_same_answer_gives_the_same_response_as_decoding_afresh() -> None:
    carrier = SerialCarrier(FC)
    first = carrier.decode(answer_data(FC, 1613, 500), 0.001)
    again = carrier.decode(answer_data(FC, 1613, 500, status=0x0E07), 0.002)
    assert again.response is first.response  # the same PKW bytes: decoded once
    fresh = pkw.decode_response(again.pkw, FC.dialect, FC.ind_layout)
    assert again.response == fresh
    assert (again.status_word, again.duration) == (0x0E07, 0.002)  # the rest is this answer's


def test_another_value_or_parameter_is_decoded_anew() -> None:
    carrier = SerialCarrier(FC)
    first = carrier.decode(answer_data(FC, 1613, 500), 0.001)
    other = carrier.decode(answer_data(FC, 1613, 501), 0.001)
    elsewhere = carrier.decode(answer_data(FC, 1614, 500), 0.001)
    assert isinstance(other.response, pkw.ValueResponse)
    assert isinstance(elsewhere.response, pkw.ValueResponse)
    assert (other.response.pnu, other.response.raw) == (1613, 501)
    assert (elsewhere.response.pnu, elsewhere.response.raw) == (1614, 500)
    assert first.response is not other.response


def test_more_answers_than_kept_still_decode_right() -> None:
    carrier = SerialCarrier(FC)
    for raw in range(3 * _KEPT_ANSWERS):
        found = carrier.decode(answer_data(FC, 1613, raw), 0.001).response
        assert isinstance(found, pkw.ValueResponse)
        assert found.raw == raw


def test_an_answer_that_does_not_decode_is_not_kept() -> None:
    carrier = SerialCarrier(FC)
    head = (0xE000 | 1613).to_bytes(2, "big") + b"\x00\x00"  # AK 14: not in the FC table
    bad = encode_block(head + b"\x00\x00\x00\x01", (0x0607, 0))
    for _ in range(2):
        answer = carrier.decode(bad, 0.001)
        assert answer.response is None
        assert answer.why


def response(raw: int) -> pkw.ValueResponse:
    return pkw.ValueResponse(2, 1613, 0, raw, Width.DWORD)


def test_a_value_kept_is_the_one_decoding_afresh_gives() -> None:
    values, fmt = DecodedValues(), ParameterDescription(vtype=ValueType.U32)
    read = pkw.read(FC.dialect, 1613)
    answered = Answered(response(500))
    first = values.result("d1", answered, None, read, fmt)
    again = values.result("d1", Answered(answered.response), None, read, fmt)
    assert (again.raw, again.value) == (first.raw, first.value) == (500, 500)
    assert again == job_result(Answered(answered.response), None, read, fmt)


def test_another_notation_response_or_drive_is_decoded_anew() -> None:
    values = DecodedValues()
    plain = ParameterDescription(vtype=ValueType.U32)
    tenths = ParameterDescription(vtype=ValueType.U32, scaling=Scaling.scale(0.1))
    read = pkw.read(FC.dialect, 1613)
    same = response(500)
    assert values.result("d1", Answered(same), None, read, plain).value == 500
    assert values.result("d1", Answered(same), None, read, tenths).value == 50
    assert values.result("d1", Answered(response(600)), None, read, tenths).value == 60
    assert values.result("d2", Answered(same), None, read, plain).value == 500
    assert len(values) == 2  # one parameter of each drive
    values.forget("d1")
    assert len(values) == 1


def test_no_answer_has_no_value() -> None:
    values, fmt = DecodedValues(), ParameterDescription(vtype=ValueType.U32)
    result = values.result("d1", TimedOut("no answer"), None, pkw.read(FC.dialect, 1613), fmt)
    assert result.value is None
    assert len(values) == 0
