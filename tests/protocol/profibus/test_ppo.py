"""PPO layouts, the never-take-control rule, and the PKW slot over Data_Exchange."""

from __future__ import annotations

import inspect

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol import pkw, pzd
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Command, Dialect, IndLayout, dialect
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dp_services
from pkwbus.protocol.profibus.dp.ppo import PkwSlot, ppo_type
from pkwbus.protocol.pzd import Profile

PROFIDRIVE = ppo.dp_dialect("profidrive")
PCV = ppo.dp_dialect("danfoss-pcv")
HITACHI = ppo.dp_dialect("hitachi-sjpb")
PPO1 = ppo_type(1)


@pytest.mark.parametrize(
    ("number", "pkw_words", "pzd_words", "cfg"),
    [(1, 4, 2, "F3 F1"), (2, 4, 6, "F3 F5"), (3, 0, 2, "F1"), (4, 0, 6, "F5"), (5, 4, 10, "F3 F9")],
)
def test_ppo_table(number: int, pkw_words: int, pzd_words: int, cfg: str) -> None:
    kind = ppo_type(number)
    assert (kind.pkw_words, kind.pzd_words, kind.cfg) == (pkw_words, pzd_words, bytes.fromhex(cfg))
    # The configuration identifiers set up exactly the PPO's bytes in each direction.
    assert dp_services.io_lengths(kind.cfg) == (kind.length, kind.length)


def test_unknown_ppo_and_dialect() -> None:
    with pytest.raises(LocalProtocolError, match="PPO 6"):
        ppo_type(6)
    with pytest.raises(LocalProtocolError, match="not used over PROFIBUS"):
        ppo.dp_dialect("fc")


def test_siemens_example_read_p7841_index_2() -> None:
    # CU240 operating instructions, table 6-17: PKE 0x6731, IND 0x0290.
    request = pkw.read(PROFIDRIVE, 7841, 2)
    wire = ppo.encode_ppo_write(PPO1, PROFIDRIVE, request)
    assert wire == bytes.fromhex("6731 0290 0000 0000 0000 0000")


def test_danfoss_pcv_subindex_in_ind_high_byte() -> None:
    assert ppo.encode_ppo_write(PPO1, PCV, pkw.read(PCV, 1613))[:8] == bytes.fromhex(
        "164D 0000 0000 0000"
    )
    assert ppo.encode_ppo_write(PPO1, PCV, pkw.read(PCV, 100, 3))[:4] == bytes.fromhex("6064 0300")
    write = pkw.write(PCV, 302, 1500, pkw.Width.DWORD)
    assert ppo.encode_ppo_write(PPO1, PCV, write)[:8] == bytes.fromhex("312E 0000 0000 05DC")


def test_hitachi_has_no_description_or_array_double_word() -> None:
    with pytest.raises(LocalProtocolError, match="hitachi-sjpb"):
        pkw.read_description(HITACHI, 1, 1)
    with pytest.raises(LocalProtocolError, match="hitachi-sjpb"):
        pkw.write(HITACHI, 1, 1, pkw.Width.DWORD, index=1)
    assert ppo.encode_ppo_write(PPO1, HITACHI, pkw.read(HITACHI, 1, 2))[:4] == bytes.fromhex(
        "6001 0200"
    )


def test_idle_ppo_write_is_ak_0_and_zero_process_data() -> None:
    for number, kind in ppo.PPO_TYPES.items():
        assert ppo.encode_ppo_write(kind, PCV) == bytes(kind.length), number


def test_no_parameter_channel_in_ppo_3_and_4() -> None:
    with pytest.raises(LocalProtocolError, match="no parameter channel"):
        ppo.encode_ppo_write(ppo_type(3), PCV, pkw.read(PCV, 1))
    with pytest.raises(LocalProtocolError, match="no parameter channel"):
        PkwSlot(ppo_type(4), PCV).submit(pkw.read(PCV, 1))


def test_the_control_word_cannot_be_chosen() -> None:
    parameters = list(inspect.signature(ppo.encode_ppo_write).parameters)
    assert parameters == ["ppo", "dia", "request"]


requests = st.sampled_from(ppo.DP_DIALECTS).flatmap(
    lambda name: st.tuples(
        st.just(ppo.dp_dialect(name)),
        st.sampled_from(
            [c for c in Command if c is not Command.TEXT and ppo.dp_dialect(name).has(c)]
        ),
        st.integers(0, 1999),
        st.integers(0, 255),
        st.integers(0, 0xFFFF),
    )
)


@settings(deadline=None)
@given(st.sampled_from(sorted(ppo.PPO_TYPES)), requests)
def test_every_ppo_write_leaves_control_alone(
    number: int, args: tuple[pkw.Dialect, Command, int, int, int]
) -> None:
    dia, command, pnu, sub, value = args
    kind = ppo_type(number)
    req = pkw.request(dia, command, pnu, subindex=sub, value=value)
    if not kind.has_pkw and command is not Command.NONE:
        with pytest.raises(LocalProtocolError):
            ppo.encode_ppo_write(kind, dia, req)
        return
    wire = ppo.encode_ppo_write(kind, dia, req)
    assert len(wire) == kind.length
    pzd_part = wire[2 * kind.pkw_words :]
    ctw = int.from_bytes(pzd_part[:2], "big")
    assert not pzd.takes_control(ctw) and ctw == 0
    assert pzd_part == bytes(len(pzd_part))
    if kind.has_pkw:
        decoded = pkw.decode_request(wire[:8], dia, IndLayout.PROFIDRIVE)
        assert (decoded.ak, decoded.pnu, decoded.subindex) == (req.ak, req.pnu, req.subindex)


# ------------------------------------------------------------------- PPO-read


def ppo_read(response: pkw.PkwResponse, dia: pkw.Dialect, zsw: int = 0, mav: int = 0) -> bytes:
    head = pkw.encode_response(response, dia, IndLayout.PROFIDRIVE, 4)
    return head + zsw.to_bytes(2, "big") + mav.to_bytes(2, "big")


def test_ppo_read_status_word_and_actual_value() -> None:
    status = pzd.status_word(Profile.PROFIDRIVE, ready=True, operation_enabled=True)
    data = ppo_read(pkw.NoResponse(0, 0, 0), PROFIDRIVE, status, 0x2000)
    read = ppo.decode_ppo_read(PPO1, PROFIDRIVE, data)
    assert isinstance(read.pkw, pkw.NoResponse)
    assert read.status["ready"] and read.status["operation_enabled"] and not read.status["fault"]
    assert read.main_actual_percent == 50.0
    fc_read = ppo.decode_ppo_read(PPO1, PCV, data)
    assert fc_read.profile is Profile.FC  # Danfoss drives default to the FC profile


def test_ppo_read_wrong_length_is_the_peers_error() -> None:
    with pytest.raises(RemoteProtocolError, match="10 bytes"):
        ppo.decode_ppo_read(PPO1, PCV, bytes(10))


def test_ppo_read_without_pkw() -> None:
    read = ppo.decode_ppo_read(ppo_type(4), PCV, bytes.fromhex("0607 1234") + bytes(8))
    assert read.pkw is None and read.status_word == 0x0607 and read.main_actual_value == 0x1234


# ------------------------------------------------------------------ PKW slot

IDLE = ppo_read(pkw.NoResponse(0, 0, 0), PCV)


def value(pnu: int, raw: int, sub: int = 0) -> bytes:
    return ppo_read(pkw.ValueResponse(1, pnu, sub, raw, pkw.Width.WORD), PCV)


def pkw_of(wire: bytes, dialect: Dialect = PCV) -> pkw.PkwRequest:
    return pkw.decode_request(wire[:8], dialect, IndLayout.PROFIDRIVE)


def test_slot_carries_the_request_after_the_slaves_ak_0_and_hands_on_each_answer() -> None:
    slot = PkwSlot(PPO1, PCV)
    assert slot.outputs() == bytes(12)
    request = pkw.read(PCV, 1613)
    slot.submit(request)
    # Waits for the slave's AK 0 before the new request goes out: no answer to hand on.
    assert slot.feed(value(1613, 7)).answer is None
    assert pkw_of(slot.outputs()).command is Command.NONE
    assert slot.feed(IDLE).answer is None
    for answer in (value(1614, 9), value(1613, 503)):
        assert pkw_of(slot.outputs()) == request
        update = slot.feed(answer)
        assert update.answer is not None and update.answer.request == request
        assert not update.answer.earlier  # AK 0 was seen: an answer to this request
        assert update.answer.response == update.read.pkw if update.read else False
    assert slot.cycles == 4 and slot.busy
    slot.finish()  # the job judged it: AK 0 again, and the next job waits for AK 0
    assert not slot.busy and pkw_of(slot.outputs()).command is Command.NONE


def test_an_answer_before_any_ak_0_may_be_an_earlier_ones() -> None:
    slot = PkwSlot(PPO1, PCV)
    slot.submit(pkw.write(PCV, 302, 1500, pkw.Width.WORD))
    for _ in range(ppo.IDLE_WAIT_CYCLES):
        assert slot.feed(value(302, 1400)).answer is None
    update = slot.feed(value(302, 1400))
    assert update.answer is not None and update.answer.earlier


def test_slot_refuses_a_second_job_and_ak_0() -> None:
    slot = PkwSlot(PPO1, PCV)
    slot.submit(pkw.read(PCV, 1))
    with pytest.raises(LocalProtocolError, match="already under way"):
        slot.submit(pkw.read(PCV, 2))
    with pytest.raises(LocalProtocolError, match="AK 0"):
        PkwSlot(PPO1, PCV).submit(pkw.none_request(PCV))


def test_slot_gives_up_waiting_for_ak_0() -> None:
    slot = PkwSlot(PPO1, PCV)
    slot.submit(pkw.read(PCV, 5))
    for _ in range(ppo.IDLE_WAIT_CYCLES):
        assert pkw_of(slot.outputs()).command is Command.NONE
        slot.feed(value(4, 1))
    assert pkw_of(slot.outputs()).pnu == 5


def test_slot_undecodable_read_is_reported_not_raised() -> None:
    slot = PkwSlot(PPO1, PCV)
    update = slot.feed(bytes(3))
    assert update.read is None and "3 bytes" in update.error


@pytest.mark.parametrize("dialect", ["danfoss-pcv", "profidrive", "hitachi-sjpb"])
def test_answers_that_are_no_pkw_answers_end_the_wait_for_ak_0(dialect: str) -> None:
    """A slave whose PPO-reads are no PKW answer of the dialect (all bytes FF): a job still
    goes out once the wait for AK 0 has run out, and each answer tells the request."""
    d = ppo.dp_dialect(dialect)
    slot = PkwSlot(PPO1, d)
    request = pkw.read(d, 5)
    slot.submit(request)
    for _ in range(ppo.IDLE_WAIT_CYCLES):
        assert pkw_of(slot.outputs(), d).command is Command.NONE
        update = slot.feed(b"\xff" * PPO1.length)
        assert update.garbled is not None and update.garbled.request is None
        assert f"no PPO 1 answer of the {dialect} dialect" in update.error
    assert pkw_of(slot.outputs(), d).pnu == 5
    update = slot.feed(b"\xff" * PPO1.length)
    assert update.garbled is not None and update.garbled.request is request


def test_a_dialect_of_another_bus_and_a_text_do_not_go_into_a_ppo() -> None:
    """FC and USS are no PROFIBUS dialects; a text needs a variable PKW length, and a PPO's
    parameter channel is 4 fixed words."""
    uss = dialect("uss")
    with pytest.raises(LocalProtocolError, match="dialect 'uss' is not used over PROFIBUS"):
        ppo.encode_ppo_write(PPO1, uss)
    with pytest.raises(LocalProtocolError, match="dialect 'fc' is not used over PROFIBUS"):
        PkwSlot(PPO1, dialect("fc"))
    text = pkw.write_text(PROFIDRIVE, 199, b"FAN-12")
    with pytest.raises(LocalProtocolError, match="a text write does not fit the 4 PKW words"):
        ppo.encode_ppo_write(PPO1, PROFIDRIVE, text)
    with pytest.raises(LocalProtocolError, match="a text write does not fit the 4 PKW words"):
        PkwSlot(PPO1, PROFIDRIVE).submit(text)
