"""PPO layouts, the never-take-control rule, and the PKW slot over Data_Exchange."""

from __future__ import annotations

import inspect

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol import dp_services, pkw, ppo, pzd
from pkwbus.protocol.dialects import Command, IndLayout
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.ppo import JobDone, JobExpired, PkwSlot, ppo_type
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
        PkwSlot(ppo_type(4), PCV).submit(pkw.read(PCV, 1), 1.0)


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


def pkw_of(wire: bytes) -> pkw.PkwRequest:
    return pkw.decode_request(wire[:8], PCV, IndLayout.PROFIDRIVE)


def test_slot_repeats_the_request_until_the_matching_answer() -> None:
    slot = PkwSlot(PPO1, PCV)
    assert slot.outputs() == bytes(12)
    request = pkw.read(PCV, 1613)
    slot.submit(request, deadline=10.0)
    # Waits for the slave's AK 0 before the new request goes out.
    assert slot.feed(value(1613, 7), 0.1).done is None
    assert pkw_of(slot.outputs()).command is Command.NONE
    slot.feed(IDLE, 0.2)
    for t, answer in ((0.3, IDLE), (0.4, value(1614, 9)), (0.5, IDLE)):
        assert pkw_of(slot.outputs()) == request
        assert slot.feed(answer, t).done is None
    assert pkw_of(slot.outputs()) == request
    update = slot.feed(value(1613, 503), 0.6)
    assert (
        isinstance(update.done, JobDone) and update.done.cycles == 6
    )  # 2 waiting for AK 0, 4 with the request
    assert isinstance(update.done.response, pkw.ValueResponse) and update.done.response.raw == 503
    assert not slot.busy and pkw_of(slot.outputs()).command is Command.NONE


def test_slot_write_needs_the_echo() -> None:
    slot = PkwSlot(PPO1, PCV)
    slot.feed(IDLE, 0.0)
    request = pkw.write(PCV, 302, 1500, pkw.Width.WORD)
    slot.submit(request, deadline=10.0)
    assert slot.feed(IDLE, 0.1).done is None  # AK 0 while the slave works: not yet
    done = slot.feed(value(302, 1500), 0.2).done
    assert isinstance(done, JobDone) and not done.mismatch


def test_a_write_acknowledged_with_another_value_ends_at_once() -> None:
    """After the AK 0 handshake no stale answer can come: another value echoed is what the
    slave took, and the job ends instead of writing it again every cycle."""
    slot = PkwSlot(PPO1, PCV)
    slot.feed(IDLE, 0.0)
    slot.submit(pkw.write(PCV, 302, 1500, pkw.Width.WORD), deadline=10.0)
    done = slot.feed(value(302, 1400), 0.1).done
    assert isinstance(done, JobDone) and done.mismatch
    assert not slot.busy and pkw_of(slot.outputs()).command is Command.NONE


def test_slot_rejection_finishes_the_job() -> None:
    slot = PkwSlot(PPO1, PCV)
    slot.feed(IDLE, 0.0)
    slot.submit(pkw.read(PCV, 9999 % 2048), deadline=10.0)
    rejected = ppo_read(pkw.Rejection(7, 9999 % 2048, 0, 0, "Illegal PNU", "x"), PCV)
    done = slot.feed(rejected, 0.1).done
    assert isinstance(done, JobDone) and isinstance(done.response, pkw.Rejection)


def test_slot_deadline() -> None:
    slot = PkwSlot(PPO1, PCV)
    slot.feed(IDLE, 0.0)
    slot.submit(pkw.read(PCV, 1), deadline=1.0)
    assert slot.feed(IDLE, 0.5).done is None
    assert slot.expire(0.9) is None
    done = slot.feed(IDLE, 1.0).done
    assert isinstance(done, JobExpired) and done.cycles == 2
    slot.submit(pkw.read(PCV, 1), deadline=2.0)
    assert isinstance(slot.expire(2.0), JobExpired)  # also without an exchange


def test_slot_refuses_a_second_job_and_ak_0() -> None:
    slot = PkwSlot(PPO1, PCV)
    slot.submit(pkw.read(PCV, 1), 1.0)
    with pytest.raises(LocalProtocolError, match="already under way"):
        slot.submit(pkw.read(PCV, 2), 1.0)
    with pytest.raises(LocalProtocolError, match="AK 0"):
        PkwSlot(PPO1, PCV).submit(pkw.none_request(PCV), 1.0)


def test_slot_gives_up_waiting_for_ak_0() -> None:
    slot = PkwSlot(PPO1, PCV)
    slot.submit(pkw.read(PCV, 5), 100.0)
    for n in range(ppo.IDLE_WAIT_CYCLES):
        assert pkw_of(slot.outputs()).command is Command.NONE
        slot.feed(value(4, 1), float(n))
    assert pkw_of(slot.outputs()).pnu == 5


def test_slot_undecodable_read_is_reported_not_raised() -> None:
    slot = PkwSlot(PPO1, PCV)
    update = slot.feed(bytes(3), 0.0)
    assert update.read is None and "3 bytes" in update.error


answers = st.one_of(
    st.just(IDLE),
    st.builds(value, st.integers(0, 3), st.integers(0, 3)),
    st.binary(min_size=12, max_size=12),
)


@settings(deadline=None)
@given(st.integers(0, 3), st.lists(answers, max_size=30))
def test_slot_never_finishes_on_a_non_matching_answer(pnu: int, reads: list[bytes]) -> None:
    slot = PkwSlot(PPO1, PCV)
    request = pkw.read(PCV, pnu)
    slot.submit(request, deadline=1000.0)
    for n, data in enumerate(reads):
        wire = slot.outputs()
        assert wire[8:] == bytes(4)  # never a control word
        sent = pkw_of(wire)
        assert sent.command in (Command.NONE, Command.READ)
        update = slot.feed(data, float(n))
        if isinstance(update.done, JobDone):
            assert sent == request
            assert pkw.matches(request, update.done.response, PCV)
            break
        assert update.done is None


def test_without_the_ak0_handshake_another_value_is_not_yet_a_mismatch() -> None:
    """A slave that never showed AK 0 before the job went out may still be telling an
    earlier answer for the same parameter: not a mismatch, the request goes on."""
    slot = PkwSlot(PPO1, PCV)
    slot.submit(pkw.write(PCV, 302, 1500, pkw.Width.WORD), deadline=10.0)
    for n in range(ppo.IDLE_WAIT_CYCLES):  # the slave keeps answering its poll of 302
        assert slot.feed(value(302, 1400), n * 0.01).done is None
    assert pkw_of(slot.outputs()).command is not Command.NONE  # the change goes out now
    assert slot.feed(value(302, 1400), 0.2).done is None  # still an earlier answer, maybe
    done = slot.feed(value(302, 1500), 0.3).done
    assert isinstance(done, JobDone) and not done.mismatch
