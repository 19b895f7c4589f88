"""pkwbus's defaults against simulated Siemens drives as they leave the factory (a variable
PKW length), and against drives set to 4 or 3 fixed words: every read and every change lands
as asked, a word change never goes out before its place is known, and a change acknowledged
with another value ends at once as a mismatch."""

from __future__ import annotations

import struct
from typing import Any

import pytest

from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.answers import Reply
from pkwbus.master.planning.carrier import Item
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.outcomes import Answered, Mismatch, NotSent, Rejected
from pkwbus.master.planning.plan import PkwLengthTold
from pkwbus.master.planning.planner import Planner
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.protocol.pkw.length import VARIABLE
from pkwbus.protocol.serial.telegram import BlockShape, split_block
from pkwbus.protocol.values import ValueType
from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.drives.table import USS_TABLE, ParamSpec
from tests.master.conftest import make_sim, open_port, run_job, serve
from tests.master.planning.test_planner import FakeLine, drives

# A word parameter that may change while the motor runs (the table's p0304 may not).
WORD = ParamSpec(2010, "p2010", ValueType.U16, 0, "", 0.0, 13.0, True, initial=6.0)
SPECS = (*USS_TABLE, WORD)


def sim_with(pkw_words: int | None, **kw: Any) -> Simulator:
    return make_sim("uss", [1], specs=SPECS, pkw_words=pkw_words, **kw)


DIALECTS = ["uss", "profidrive"]  # the two that ride on USS framing, each with its IND layout


def raw(outcome: object) -> int:
    assert isinstance(outcome, Answered), outcome
    assert isinstance(outcome.response, pkw.ValueResponse)
    return outcome.response.raw


def f32(value: float) -> int:
    return int.from_bytes(struct.pack(">f", value), "big")


def write_telegrams(tx: list[bytes], pnu: int, name: str = "uss") -> list[bytes]:
    """The change requests among ``tx`` for ``pnu`` (decoded as a follower decodes them)."""
    dialect = DriveTarget.create("uss", 1, dialect_name=name).dialect
    out = []
    for t in tx:
        block = split_block(t[3:-1], BlockShape(None, 2))
        req = pkw.decode_request(block.pkw, dialect, dialect.default_ind_layout, None)
        if req.is_write and req.pnu == pnu:
            out.append(t)
    return out


@pytest.mark.parametrize("dialect", DIALECTS)
@pytest.mark.parametrize("sim_words", [VARIABLE, 4])
async def test_the_defaults_read_and_change_words_and_floats(
    end: str, sim_words: int | None, dialect: str
) -> None:
    """Reads of a word and a float, changes of a word and a double word, each landing as
    asked, whether the drive is as the factory set it (127) or set to 4 fixed words."""
    sim = sim_with(sim_words, dialect=dialect)
    drive = sim.drives[1]
    target = DriveTarget.create("uss", 1, dialect_name=dialect)  # pkw_words: auto, the default
    d = target.dialect
    async with serve(sim, end) as port, open_port(port, "uss") as (line, trace):
        assert raw(await run_job(line, target, pkw.read(d, 2010))) == 6
        assert raw(await run_job(line, target, pkw.read(d, 1120))) == f32(10.0)
        assert raw(await run_job(line, target, pkw.read(d, 947, 0))) == drive.value(947, 0)
        word = await run_job(line, target, pkw.write(d, 2010, 9, pkw.Width.WORD))
        assert raw(word) == 9
        dword = await run_job(line, target, pkw.write(d, 1120, f32(12.5), pkw.Width.DWORD))
        assert raw(dword) == f32(12.5)
    assert drive.value(2010) == 9
    assert drive.value(1120) == f32(12.5)
    # the word change went out once, in the drive's own form
    (change,) = write_telegrams(trace.tx, 2010, dialect)
    pkw_words = (len(change) - 4) // 2 - 2
    assert pkw_words == (3 if sim_words is VARIABLE else 4)
    assert not sim.stats.as_dict().get("malformed")


async def test_a_word_change_to_a_fixed_3_drive(end: str) -> None:
    sim = sim_with(3)
    target = DriveTarget.create("uss", 1, pkw_words=3)
    async with serve(sim, end) as port, open_port(port, "uss") as (line, _):
        assert (
            raw(await run_job(line, target, pkw.write(target.dialect, 2010, 11, pkw.Width.WORD)))
            == 11
        )
    assert sim.drives[1].value(2010) == 11


async def test_a_configured_length_the_drive_contradicts_sends_no_change(end: str) -> None:
    """pkw_words: 4 against a factory-set drive: reads decode by their length, and a change
    is refused before it goes out (it would put 0 on the drive)."""
    sim = sim_with(VARIABLE)
    target = DriveTarget.create("uss", 1, pkw_words=4)
    d = target.dialect
    async with serve(sim, end) as port, open_port(port, "uss") as (line, trace):
        assert raw(await run_job(line, target, pkw.read(d, 2010))) == 6
        outcome = await run_job(line, target, pkw.write(d, 2010, 9, pkw.Width.WORD))
    assert isinstance(outcome, NotSent), outcome
    assert "127" in outcome.reason and "4" in outcome.reason
    assert not write_telegrams(trace.tx, 2010)
    assert sim.drives[1].value(2010) == 6


async def test_a_change_acknowledged_with_another_value_ends_after_one_exchange(
    end: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A drive that takes something else than sent: one change request, then the mismatch;
    nothing is written again."""
    sim = sim_with(VARIABLE)
    drive = sim.drives[1]
    store = drive.params._write

    def clamped(spec: ParamSpec, req: pkw.PkwRequest) -> None:
        store(spec, req)
        drive.params.raw[spec.pnu, req.subindex] = 4  # the drive holds another value

    monkeypatch.setattr(drive.params, "_write", clamped)
    target = DriveTarget.create("uss", 1)
    async with serve(sim, end) as port, open_port(port, "uss") as (line, trace):
        outcome = await run_job(line, target, pkw.write(target.dialect, 2010, 9, pkw.Width.WORD))
    assert isinstance(outcome, Mismatch), outcome
    assert (outcome.sent, outcome.answered) == (9, 4)
    assert len(write_telegrams(trace.tx, 2010)) == 1


def test_auto_finds_a_fixed_3_drive_by_a_short_probe() -> None:
    """A fixed-3 drive answers no 4-word request: it goes down, and while its length is not
    known every other probe has 3 words; the one it answers tells its length (fake clock)."""
    sim = Simulator("uss", [1], pkw_words=3, timing=SimTiming(response_delay=0.0), seed=7)
    policy = HealthPolicy(down_after=3, probe_initial=1.0, probe_cap=4.0)
    planner = Planner(drives("uss", [1], [52], 0.1), poll_deadline=0.5, policy=policy)
    line = FakeLine(planner, sim)
    line.run(10.0)
    told = [e.length for e in line.events if isinstance(e, PkwLengthTold)]
    assert [(t.words, t.known) for t in told] == [(3, True)]
    assert line.shown("d1") and line.polls_ok("d1") > 0
    last = line.sent[-1].telegram
    assert (len(last) - 4) // 2 - 2 == 3  # polls go out with 3 PKW words now


async def test_arrays_eeprom_descriptions_and_texts_with_the_defaults(end: str) -> None:
    """Every place the PKW length decides: an array element's change stored in EEPROM, a
    description element, a text read and a text change, against a factory-set drive."""
    array = ParamSpec(1001, "p1001", ValueType.U16, 0, "", 0.0, 100.0, True, array=3)
    text = ParamSpec(199, "p0199", ValueType.TEXT, writable=True, initial="PUMP-7")
    sim = make_sim("uss", [1], specs=(*SPECS, array, text), pkw_words=VARIABLE)
    drive = sim.drives[1]
    target = DriveTarget.create("uss", 1)
    d = target.dialect
    store = pkw.Store.EEPROM
    async with serve(sim, end) as port, open_port(port, "uss") as (line, trace):
        changed = await run_job(
            line, target, pkw.write(d, 1001, 42, pkw.Width.WORD, index=2, store=store)
        )
        assert raw(changed) == 42
        element = await run_job(line, target, pkw.read_description(d, 1120, 1))
        assert isinstance(element, Answered) and isinstance(
            element.response, pkw.DescriptionResponse
        )
        assert element.response.width is pkw.Width.WORD
        named = await run_job(line, target, pkw.read_text(d, 199))
        assert isinstance(named, Answered) and isinstance(named.response, pkw.TextResponse)
        assert named.response.text == b"PUMP-7"
        written = await run_job(line, target, pkw.write_text(d, 199, b"FAN-12"))
        assert isinstance(written, Answered), written
    assert drive.value(1001, 2) == 42 and drive.eeprom[1001, 2] == 42
    assert drive.value(1001, 0) == 0  # the other elements untouched
    assert drive.text(199) == b"FAN-12"
    (change,) = write_telegrams(trace.tx, 1001)
    assert (len(change) - 4) // 2 - 2 == 3  # PKE IND PWE1: the word in PWE1


def down_then_back(sim: Simulator) -> FakeLine:
    """Drive 1 dead for the first seconds of a line on a fake clock, then answering."""
    sim.kill(1)
    policy = HealthPolicy(down_after=3, probe_initial=1.0, probe_cap=2.0)
    planner = Planner(drives("uss", [1], [52, 1120], 0.1), poll_deadline=0.5, policy=policy)
    line = FakeLine(planner, sim)
    line.run(5.0)
    sim.revive(1)
    line.run(5.0)
    return line


def test_a_factory_set_drive_found_by_a_short_probe_is_variable_not_fixed_3() -> None:
    """A variable drive off at start-up answers the 3-word probe with another length than
    3 words: it is learned variable (a fixed-3 drive would answer with 3)."""
    sim = Simulator("uss", [1], specs=SPECS, timing=SimTiming(response_delay=0.0), seed=7)
    line = down_then_back(sim)
    told = [e.length for e in line.events if isinstance(e, PkwLengthTold)]
    assert told and (told[-1].words, told[-1].known) == (VARIABLE, True)
    assert all(t.words != 3 for t in told)
    assert line.polls_ok("d1") > 0


def test_a_double_word_change_to_a_fixed_3_drive_ends_unsent() -> None:
    """What the drive's 3 PKW words cannot carry ends as not sent, the line going on (no
    exception out of the planner, no job left unfinished)."""
    sim = Simulator("uss", [1], specs=SPECS, pkw_words=3, timing=SimTiming(response_delay=0.0))
    line = down_then_back(sim)
    dialect = line.planner.drives[0].carrier.dialect
    job = line.submit("d1", pkw.write(dialect, 1120, f32(12.5), pkw.Width.DWORD))
    line.run(1.0)
    (finished,) = line.finished(job)
    assert isinstance(finished.outcome, NotSent), finished.outcome
    assert "3 PKW words" in finished.outcome.reason
    assert sim.drives[1].value(1120) == f32(10.0)
    polls = line.polls_ok("d1")
    line.run(1.0)
    assert line.polls_ok("d1") > polls  # the line goes on


def test_a_repeated_rejection_of_the_read_is_not_the_changes() -> None:
    """The read before a change was refused; the same refusal repeated by a lagging drive
    is "not yet" for the change, not its rejection."""
    target = DriveTarget.create("uss", 1, pkw_words=VARIABLE)
    d = target.dialect
    refusal = pkw.encode_response(
        pkw.Rejection(7, 2010, 0, 4, "", ""), d, target.ind_layout, VARIABLE
    )
    change = carrier_for(target).transaction(
        [Item(pkw.write(d, 2010, 9, pkw.Width.WORD))], retries=2, deadline=10.0, stale=refusal
    )
    repeated = Reply(1, refusal + bytes(4), 0.001)
    assert change.feed(repeated, 0.0) is None and change.waiting
    other = pkw.encode_response(
        pkw.Rejection(7, 2010, 0, 2, "", ""), d, target.ind_layout, VARIABLE
    )
    outcome = change.feed(Reply(1, other + bytes(4), 0.001), 0.1)
    assert isinstance(outcome, Rejected) and outcome.fault == 2


async def test_the_read_before_a_change_of_element_0_reads_that_element(end: str) -> None:
    array = ParamSpec(1001, "p1001", ValueType.U16, 0, "", 0.0, 100.0, True, array=3)
    sim = make_sim("uss", [1], specs=(*SPECS, array), pkw_words=VARIABLE)
    target = DriveTarget.create("uss", 1)
    d = target.dialect
    async with serve(sim, end) as port, open_port(port, "uss") as (line, trace):
        assert raw(await run_job(line, target, pkw.write(d, 1001, 7, pkw.Width.WORD, index=0))) == 7
    first = split_block(trace.tx[0][3:-1], BlockShape(None, 2)).pkw
    read = pkw.decode_request(first, d, d.default_ind_layout, VARIABLE)
    assert read.command is Command.READ_ARRAY and (read.pnu, read.subindex) == (1001, 0)
