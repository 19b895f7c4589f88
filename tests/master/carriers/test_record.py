"""Several PKW jobs as one data record 47 request (the record carrier and its batch
transaction), and the planner that batches a DP-V1 slave's due polls: pure, on a fake
clock."""

from __future__ import annotations

import struct

import pytest

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.carriers import RecordCarrier
from pkwbus.master.planning.answers import ErrorKind, Failure, Reply
from pkwbus.master.planning.carrier import Item as RecordItem
from pkwbus.master.planning.outcomes import Answered, LineFailed, NotSent, Rejected, TimedOut
from pkwbus.master.planning.plan import DriveSpec, Finished, PollSpec, Send
from pkwbus.master.planning.planner import Planner
from pkwbus.master.planning.transaction import BatchTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profidrive.drive import decode_request, encode_response
from pkwbus.protocol.profidrive.parameters import (
    Format,
    ParameterError,
    RequestId,
    Values,
    decode_response,
)
from pkwbus.protocol.values.types import ValueType

SIEMENS = ppo.dp_dialect("profidrive")
DANFOSS = ppo.dp_dialect("danfoss-pcv")


def target(axis: int = 1, max_data: int = 240, reference: int = 1) -> RecordCarrier:
    return RecordCarrier(8, SIEMENS, axis, max_data, first_reference=reference)


def RecordTransaction(
    carrier: RecordCarrier, items: list[RecordItem], *, reference: int, axis: int,
    retries: int, deadline: float,
) -> BatchTransaction:  # fmt: skip
    carrier = RecordCarrier(8, carrier.dialect, axis, carrier.max_data,
                            first_reference=reference)  # fmt: skip
    return carrier.transaction(items, retries=retries, deadline=deadline)


def answer(tx: BatchTransaction, results: list[object]) -> Reply:
    """The drive's response to the transaction's request, built on the drive's side."""
    request = decode_request(tx.telegram)
    return Reply(8, encode_response(request, results), 0.01)  # type: ignore[arg-type]


def test_reads_together_each_with_its_own_outcome_and_type() -> None:
    items = [
        RecordItem(pkw.read(SIEMENS, 21), ValueType.U32),  # the catalog says u32...
        RecordItem(pkw.read(SIEMENS, 52), ValueType.U16),
        RecordItem(pkw.read(SIEMENS, 9999)),
    ]
    tx = RecordTransaction(target(), items, reference=7, axis=1, retries=2, deadline=10.0)
    assert decode_request(tx.telegram).addresses[2].pnu == 9999
    got = tx.feed(
        answer(tx, [Values(Format.FLOAT, (50.0,)), Values(Format.U16, (0x1234,)),
                    ParameterError(0)]),
        0.1,
    )  # fmt: skip
    assert got is not None
    speed, status, unknown = tx.outcomes
    assert isinstance(speed, Answered) and isinstance(speed.response, pkw.ValueResponse)
    # ...the drive answers FloatingPoint: a float, whatever the catalog says.
    assert speed.response.vtype is ValueType.F32
    assert ParameterDescription(vtype=ValueType.U32).value_of(speed.response)[1] == 50.0
    assert struct.pack(">I", speed.response.raw) == struct.pack(">f", 50.0)
    assert isinstance(status, Answered) and status.response.raw == 0x1234  # type: ignore[union-attr]
    assert isinstance(unknown, Rejected) and unknown.fault == 0
    assert unknown.text == "Illegal parameter number"
    assert tx.tally.telegrams == 1 and tx.tally.retries == 0


def test_a_failed_transfer_is_tried_again_then_every_job_times_out() -> None:
    items = [RecordItem(pkw.read(SIEMENS, 21)), RecordItem(pkw.read(SIEMENS, 27))]
    tx = RecordTransaction(target(), items, reference=1, axis=1, retries=1, deadline=10.0)
    assert tx.feed(Failure(ErrorKind.TIMEOUT, "response timeout"), 0.1) is None
    wrong = Reply(8, bytes((9, 1, 1, 2)), 0.01)  # another request's reference
    outcome = tx.feed(wrong, 0.2)
    assert isinstance(outcome, TimedOut) and "another request" in outcome.reason
    assert all(o is outcome for o in tx.outcomes) and len(tx.outcomes) == 2
    assert tx.tally.errors[ErrorKind.UNEXPECTED] == 1 and tx.tally.retries == 1


def test_a_lost_port_ends_it_at_once() -> None:
    tx = RecordTransaction(target(), [RecordItem(pkw.read(SIEMENS, 21))], reference=1, axis=1,
                           retries=5, deadline=10.0)  # fmt: skip
    assert isinstance(tx.feed(Failure(ErrorKind.PORT, "gone"), 0.1), LineFailed)


def test_a_change_in_its_own_format_and_done_without_an_echo() -> None:
    raw = struct.unpack(">I", struct.pack(">f", 12.15))[0]
    change = pkw.write(SIEMENS, 1121, raw, pkw.Width.DWORD)
    tx = RecordTransaction(target(), [RecordItem(change, ValueType.F32)], reference=0x80,
                           axis=1, retries=1, deadline=10.0)  # fmt: skip
    # The G120X operating instructions' example, byte for byte.
    assert tx.telegram == bytes.fromhex("80 02 01 01 10 01 04 61 00 00 08 01 41 42 66 66")
    outcome = tx.feed(answer(tx, [None]), 0.1)
    assert isinstance(outcome, Answered) and isinstance(outcome.response, pkw.ChangeDone)
    signed = pkw.write(SIEMENS, 1000, 0xFFFE, pkw.Width.WORD)
    tx = RecordTransaction(target(), [RecordItem(signed, ValueType.I16)], reference=2, axis=1,
                           retries=1, deadline=10.0)  # fmt: skip
    assert decode_request(tx.telegram).changes == (Values(Format.I16, (-2,)),)


def test_a_change_to_eeprom_is_refused_unsent() -> None:
    eeprom = pkw.write(SIEMENS, 1121, 5, pkw.Width.DWORD, store=pkw.Store.EEPROM)
    with pytest.raises(LocalProtocolError, match="RAM only"):
        RecordTransaction(target(), [RecordItem(eeprom)], reference=1, axis=1, retries=1,
                          deadline=1.0)  # fmt: skip


def test_a_change_goes_alone() -> None:
    change = pkw.write(SIEMENS, 1121, 5, pkw.Width.DWORD)
    with pytest.raises(LocalProtocolError, match="alone"):
        RecordTransaction(target(), [RecordItem(change), RecordItem(pkw.read(SIEMENS, 21))],
                          reference=1, axis=1, retries=1, deadline=1.0)  # fmt: skip


def polls(count: int, every: float = 1.0) -> tuple[PollSpec, ...]:
    return tuple(
        PollSpec(f"r{20 + n:04d}", 0, pkw.read(SIEMENS, 20 + n), every,
                 ParameterDescription(vtype=ValueType.F32))
        for n in range(count)
    )  # fmt: skip


def test_the_planner_sends_a_slaves_due_polls_in_one_request_and_keeps_them_together() -> None:
    spec = DriveSpec("pump", target(), polls(45))
    planner = Planner([spec], poll_deadline=2.0, retries=1)
    planner.line_up(0.0)
    send = planner.next_for("pump", 0.0)
    assert isinstance(send, Send)
    request = decode_request(send.telegram)
    assert len(request.addresses) == 39  # as many as one request takes
    tx = planner.active("pump")
    assert isinstance(tx, BatchTransaction)
    results = [Values(Format.FLOAT, (float(n),)) for n in range(39)]
    planner.exchanged(send, answer(tx, results), 0.05)
    finished = [e for e in planner.take_events() if isinstance(e, Finished)]
    assert len(finished) == 39
    assert [e.tally is not None for e in finished].count(True) == 1  # its cost counted once
    assert all(isinstance(e.outcome, Answered) for e in finished)
    # The other 6 go next, in their own request.
    rest = planner.next_for("pump", 0.06)
    assert rest is not None and len(decode_request(rest.telegram).addresses) == 6
    tx = planner.active("pump")
    assert isinstance(tx, BatchTransaction)
    planner.exchanged(rest, answer(tx, [Values(Format.FLOAT, (1.0,))] * 6), 0.1)
    planner.take_events()
    # A second later all 45 are due together again: the first 39 from their request's
    # due, the 6 within half an interval of them.
    nothing = planner.next_for("pump", 0.5)
    assert nothing is None
    again = planner.next_for("pump", 1.0)
    assert again is not None and len(decode_request(again.telegram).addresses) == 39
    tx = planner.active("pump")
    assert isinstance(tx, BatchTransaction)
    planner.exchanged(again, answer(tx, [Values(Format.FLOAT, (2.0,))] * 39), 1.05)
    last = planner.next_for("pump", 1.06)
    assert last is not None and len(decode_request(last.telegram).addresses) == 6
    response = decode_response(answer(planner.active("pump"), [Values(Format.FLOAT, (3.0,))] * 6)  # type: ignore[arg-type]
                               .data, decode_request(last.telegram))  # fmt: skip
    assert len(response.results) == 6


def test_a_write_goes_before_the_polls_and_alone() -> None:
    from pkwbus.master.planning.jobs import Job, JobKind, Priority

    spec = DriveSpec("pump", target(), polls(5))
    planner = Planner([spec], poll_deadline=2.0, retries=1)
    planner.line_up(0.0)
    change = pkw.write(SIEMENS, 1121, 5, pkw.Width.DWORD)
    job = Job("pump", change, JobKind.WRITE, Priority.WRITE, 5.0,
              ParameterDescription(vtype=ValueType.U32))  # fmt: skip
    planner.submit(job, 0.0)
    send = planner.next_for("pump", 0.0)
    assert send is not None
    request = decode_request(send.telegram)
    assert request.request_id is RequestId.CHANGE and len(request.addresses) == 1
    assert request.changes == (Values(Format.U32, (5,)),)


def test_a_text_poll_is_ended_unsent_and_the_others_go() -> None:
    polls = (
        PollSpec("r0021", 0, pkw.read(SIEMENS, 21), 1.0, ParameterDescription(vtype=ValueType.F32)),
        PollSpec("r0020", 0, pkw.read_text(SIEMENS, 20), 1.0,
                 ParameterDescription(vtype=ValueType.TEXT)),
    )  # fmt: skip
    planner = Planner([DriveSpec("pump", target(), polls)], poll_deadline=2.0, retries=1)
    planner.line_up(0.0)
    send = planner.next_for("pump", 0.0)
    assert send is not None
    assert [a.pnu for a in decode_request(send.telegram).addresses] == [21]
    (refused,) = [e for e in planner.take_events() if isinstance(e, Finished)]
    assert isinstance(refused.outcome, NotSent) and "text" in refused.outcome.reason


def test_the_slaves_largest_record_bounds_a_request() -> None:
    small = target(max_data=64)
    planner = Planner([DriveSpec("pump", small, polls(13))], poll_deadline=2.0, retries=1)
    planner.line_up(0.0)
    send = planner.next_for("pump", 0.0)
    assert send is not None
    request = decode_request(send.telegram)
    assert len(request.addresses) == 10  # 4 + 6 x 10 = 64 bytes each way
    assert len(send.telegram) <= 64


def test_substitute_formats_name_no_type_the_catalogs_decides() -> None:
    items = [RecordItem(pkw.read(SIEMENS, 1000), ValueType.I16),
             RecordItem(pkw.read(SIEMENS, 1121), ValueType.F32)]  # fmt: skip
    tx = RecordTransaction(target(), items, reference=1, axis=1, retries=1, deadline=10.0)
    bits = struct.unpack(">I", struct.pack(">f", 12.15))[0]
    tx.feed(answer(tx, [Values(Format.WORD, (0xFFFE,)), Values(Format.DOUBLE_WORD, (bits,))]), 0.1)
    word, dword = tx.outcomes
    assert isinstance(word, Answered) and isinstance(dword, Answered)
    assert ParameterDescription(vtype=ValueType.I16).value_of(word.response)[1] == -2
    got = ParameterDescription(vtype=ValueType.F32).value_of(dword.response)[1]
    assert got == pytest.approx(12.15, abs=1e-5)


def test_a_read_answered_without_a_value_is_tried_again_and_the_deadline_ends_it() -> None:
    tx = RecordTransaction(target(), [RecordItem(pkw.read(SIEMENS, 21))], reference=1, axis=1,
                           retries=5, deadline=1.0)  # fmt: skip
    assert tx.feed(answer(tx, [Values(Format.ZERO, ())]), 0.1) is None  # no value: not yet
    late = tx.feed(Failure(ErrorKind.TIMEOUT, "no answer"), 1.0)
    assert isinstance(late, TimedOut)


def test_a_job_in_flight_ends_at_its_deadline_while_nothing_can_go_out() -> None:
    from pkwbus.master.planning.jobs import Job, JobKind, Priority

    planner = Planner([DriveSpec("pump", target())], poll_deadline=2.0, retries=3)
    planner.line_up(0.0)
    job = Job("pump", pkw.read(SIEMENS, 21), JobKind.READ, Priority.READ, 2.0)
    planner.submit(job, 0.0)
    send = planner.next_for("pump", 0.0)
    assert send is not None
    planner.exchanged(send, Failure(ErrorKind.TIMEOUT, "the slave left data exchange"), 0.5)
    planner.take_events()
    planner.expire_queued("pump", 1.0)  # before its deadline: still in flight
    assert planner.active("pump") is not None
    planner.expire_queued("pump", 2.0)
    (done,) = [e for e in planner.take_events() if isinstance(e, Finished)]
    assert done.work is job and isinstance(done.outcome, TimedOut)
