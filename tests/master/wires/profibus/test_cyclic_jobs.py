"""A PKW job over a PROFIBUS PPO: the slot carries the request, the job's transaction judges
every answer by the one rule of every bus (the rule of the Siemens CU240 operating
instructions, "rules for editing requests and responses"): the same request until the
matching answer, a change acknowledged with another value ends at once, but not before
the slave showed AK 0 (it may still be answering an earlier request)."""

from __future__ import annotations

import logging

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.master.carriers import SlotCarrier, carrier_for
from pkwbus.master.planning.answers import ErrorKind, Failure, Reply
from pkwbus.master.planning.carrier import Item
from pkwbus.master.planning.outcomes import Answered, Mismatch, Outcome, Rejected, TimedOut
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.profibus.wire import RESTARTS_SAID_EVERY, CycleWire, SlaveSpec
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.services import Diagnosis
from pkwbus.protocol.profibus.dp.slave import SlaveSetup
from tests.protocol.profibus.test_ppo import IDLE, PCV, PPO1, pkw_of, ppo_read, value

TARGET = DriveTarget.create("profibus", 8, dialect_name="danfoss-pcv")


class Job:
    """A slot and the transaction of its job, fed one PPO-read a cycle."""

    def __init__(self, request: pkw.PkwRequest, deadline: float = 10.0) -> None:
        carrier = carrier_for(TARGET)
        assert isinstance(carrier, SlotCarrier) and carrier.ppo is PPO1
        self.slot = carrier.new_slot()
        tx = carrier.transaction([Item(request)], retries=2, deadline=deadline)
        assert isinstance(tx, PkwTransaction)
        self.tx = tx
        self.slot.submit(request)

    def cycle(self, data: bytes, now: float) -> Outcome | None:
        update = self.slot.feed(data)
        if update.answer is None:  # the wire ends a job whose deadline passed
            return self.tx.feed(PAST_DEADLINE, now) if now >= self.tx.deadline else None
        outcome = self.tx.feed(Reply(8, data, 0.001), now)  # as the DP wire hands it over
        if outcome is not None:
            self.slot.finish()
        return outcome


PAST_DEADLINE = Failure(ErrorKind.TIMEOUT, "no matching answer within the deadline")


def test_the_request_goes_on_until_the_matching_answer_and_no_retry_is_counted() -> None:
    request = pkw.read(PCV, 1613)
    job = Job(request)
    assert job.cycle(value(1613, 7), 0.1) is None  # before AK 0: not even sent
    assert job.cycle(IDLE, 0.2) is None
    for t, answer in ((0.3, IDLE), (0.4, value(1614, 9)), (0.5, IDLE)):
        assert pkw_of(job.slot.outputs()) == request
        assert job.cycle(answer, t) is None
    outcome = job.cycle(value(1613, 503), 0.6)
    assert isinstance(outcome, Answered) and isinstance(outcome.response, pkw.ValueResponse)
    assert outcome.response.raw == 503
    # Answering every cycle is how the channel works: no retry, no unexpected answer.
    assert job.tx.tally.retries == 0 and not job.tx.tally.errors
    assert pkw_of(job.slot.outputs()).command is Command.NONE


def test_a_write_needs_its_echo_and_another_value_ends_it_at_once() -> None:
    job = Job(pkw.write(PCV, 302, 1500, pkw.Width.WORD))
    job.cycle(IDLE, 0.0)
    assert job.cycle(IDLE, 0.1) is None  # AK 0 while the slave works: not yet
    assert isinstance(job.cycle(value(302, 1500), 0.2), Answered)
    other = Job(pkw.write(PCV, 302, 1500, pkw.Width.WORD))
    other.cycle(IDLE, 0.0)
    assert isinstance(other.cycle(value(302, 1400), 0.1), Mismatch)


def test_without_the_ak0_handshake_another_value_is_not_yet_a_mismatch() -> None:
    job = Job(pkw.write(PCV, 302, 1500, pkw.Width.WORD))
    for n in range(ppo.IDLE_WAIT_CYCLES):  # the slave keeps answering its poll of 302
        assert job.cycle(value(302, 1400), n * 0.01) is None
    assert job.cycle(value(302, 1400), 0.2) is None  # sent now; still an earlier answer?
    assert isinstance(job.cycle(value(302, 1500), 0.3), Answered)


def test_a_rejection_ends_the_job() -> None:
    job = Job(pkw.read(PCV, 9999 % 2048))
    job.cycle(IDLE, 0.0)
    rejected = ppo_read(pkw.Rejection(7, 9999 % 2048, 0, 0, "Illegal PNU", "x"), PCV)
    assert isinstance(job.cycle(rejected, 0.1), Rejected)


def test_the_deadline_ends_the_job() -> None:
    job = Job(pkw.read(PCV, 1), deadline=1.0)
    job.cycle(IDLE, 0.0)
    assert job.cycle(IDLE, 0.5) is None
    assert isinstance(job.cycle(IDLE, 1.0), TimedOut)


answers = st.one_of(
    st.just(IDLE),
    st.builds(value, st.integers(0, 3), st.integers(0, 3)),
    st.binary(min_size=12, max_size=12),
)


@settings(deadline=None)
@given(st.integers(0, 3), st.lists(answers, max_size=30))
def test_a_job_never_ends_on_an_answer_that_does_not_match(pnu: int, reads: list[bytes]) -> None:
    request = pkw.read(PCV, pnu)
    job = Job(request, deadline=1000.0)
    for n, data in enumerate(reads):
        wire = job.slot.outputs()
        assert wire[8:] == bytes(4)  # never a control word
        sent = pkw_of(wire)
        assert sent.command in (Command.NONE, Command.READ)
        outcome = job.cycle(data, float(n))
        if outcome is not None:
            assert sent == request
            assert isinstance(outcome, Answered | Rejected)
            assert pkw.matches(request, job.tx.response, PCV) if job.tx.response else False
            break


def test_the_ppo_write_of_a_job_is_encoded_once_by_its_carrier_and_sent_every_cycle(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The slot sends the bytes its carrier encoded for the job (the dry run's bytes) in
    every PPO-write until the job ends, and AK 0 otherwise, encoding neither again."""
    request = pkw.write(PCV, 302, 1500, pkw.Width.WORD)
    carrier = carrier_for(TARGET)
    assert isinstance(carrier, SlotCarrier)
    slot = carrier.new_slot()
    idle = slot.outputs()
    tx = carrier.transaction([Item(request)], retries=2, deadline=10.0)
    assert isinstance(tx, PkwTransaction)
    assert tx.telegram == carrier.preview(Item(request)).telegram
    encoded: list[object] = []
    real = ppo.encode_ppo_write
    monkeypatch.setattr(ppo, "encode_ppo_write", lambda *a, **k: encoded.append(a) or real(*a, **k))
    slot.submit(request, tx.telegram)
    sent = []
    for n in range(3 * ppo.IDLE_WAIT_CYCLES):
        sent.append(slot.outputs())
        slot.feed(IDLE if n < 2 else value(1614, 9))  # AK 0, then the slave's other answers
    assert sent[0] == idle  # before the slave's AK 0: not yet sent
    assert sent[-1] == tx.telegram and pkw_of(sent[-1]) == request
    slot.finish()
    assert slot.outputs() == idle
    assert encoded == []  # neither the job's PPO-write nor AK 0 was encoded again


def test_a_ppo_write_of_another_length_is_refused() -> None:
    carrier = carrier_for(TARGET)
    assert isinstance(carrier, SlotCarrier)
    slot = carrier.new_slot()
    with pytest.raises(LocalProtocolError):
        slot.submit(pkw.read(PCV, 1613), b"\x00" * 4)
    assert not slot.busy


def test_a_slave_parametrised_over_and_over_is_said_once_a_minute(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A slave that refuses its parameters is parametrised again every cycle: the first time
    is in the log at once, then one line a minute with how often, until it is in data
    exchange (then the next time is said at once again)."""
    caplog.set_level(logging.WARNING, logger="pkwbus.master.wires.profibus.wire")
    wire = CycleWire([], name="dp")
    for at in range(0, int(RESTARTS_SAID_EVERY) + 1):  # every second for a minute and one
        wire._restarted("fan", "prm_required", float(at))
    said = [r.getMessage() for r in caplog.records]
    assert said == [
        "drive fan: parametrised again (prm_required)",
        f"drive fan: parametrised again {int(RESTARTS_SAID_EVERY)} times in"
        f" {RESTARTS_SAID_EVERY:.0f} s, not in data exchange since (prm_required the last"
        " time): see its diagnosis",
    ]


@pytest.mark.parametrize(
    ("diagnosis", "cause"),
    [
        (
            Diagnosis(frozenset({"cfg_fault"}), None, 0x0402),
            "slave 8 refuses its configuration (Cfg_Fault): its modules are not those sent"
            " (ppo, cfg, gsd)",
        ),
        (
            Diagnosis(frozenset({"prm_fault"}), None, 0x1234),
            "slave 8 refuses its parameters (Prm_Fault): its ident number is 0x1234, not"
            " 0x0402 (ident, gsd)",
        ),
    ],
)
def test_the_minutes_line_of_a_refusing_slave_says_what_its_diagnosis_refuses(
    caplog: pytest.LogCaptureFixture, diagnosis: Diagnosis, cause: str
) -> None:
    """Where the slave's latest diagnosis names a fault, the line a minute says it (in the
    words of the drive's configuration), not only "see its diagnosis"."""
    caplog.set_level(logging.WARNING, logger="pkwbus.master.wires.profibus.wire")
    setup = SlaveSetup(8, 2, dps.Parameters(0x0402), b"\xf3\xf1")
    wire = CycleWire([SlaveSpec(DriveSpec("fan", carrier_for(TARGET)), setup, PPO1)], name="dp")
    wire._diagnoses["fan"] = diagnosis  # as the cycle read it
    for at in range(0, int(RESTARTS_SAID_EVERY) + 1):
        wire._restarted("fan", "prm_required", float(at))
    said = caplog.records[-1].getMessage()
    assert said.endswith(f"(prm_required the last time): {cause}")
