"""The PKW channel: seed tables, page index, IND layouts, matching rule, round trips."""

from __future__ import annotations

import contextlib
import pathlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import (
    DANFOSS_PCV,
    DIALECTS,
    FC,
    HITACHI_SJPB,
    PROFIDRIVE,
    USS,
    Command,
    Dialect,
    IndLayout,
    Reply,
    dialect,
)

# The vendor pages live beside the repository, in shared/seeds.
SEEDS = pathlib.Path(__file__).resolve().parents[4] / "shared" / "seeds"
needs_seeds = pytest.mark.skipif(not SEEDS.is_dir(), reason=f"no seed pages at {SEEDS}")


def pke_ind(req: pkw.PkwRequest, d: Dialect, layout: IndLayout) -> tuple[int, int, bytes]:
    data = pkw.encode_request(req, d, layout, 4)
    return int.from_bytes(data[:2], "big"), int.from_bytes(data[2:4], "big"), data[4:]


# ---------------------------------------------------------------- seed 003


def test_seed_003_p7841_2_in_profidrive_layout() -> None:
    req = pkw.read(PROFIDRIVE, 7841, 2)
    pke, ind, pwe = pke_ind(req, PROFIDRIVE, IndLayout.PROFIDRIVE)
    assert pke == 0x6731  # AK 6, PNU 1841
    assert ind == 0x0290  # subindex 2 in the high byte, page 0x90 low
    assert pwe == bytes(4)


def test_seed_003_p7841_2_in_uss_layout() -> None:
    req = pkw.read(USS, 7841, 2)
    pke, ind, _ = pke_ind(req, USS, IndLayout.USS)
    assert pke == 0x6731
    assert ind == 0x9002  # page 0x90 in the high byte, subindex 2 low


@pytest.mark.parametrize(
    ("offset", "page"),
    [
        (0, 0x00),
        (2000, 0x80),
        (4000, 0x10),
        (6000, 0x90),
        (8000, 0x20),
        (10000, 0xA0),
        (20000, 0x50),
        (30000, 0xF0),
        (60000, 0x74),
    ],
)
def test_page_index_values(offset: int, page: int) -> None:
    assert pkw.page_index(offset // 2000) == page
    assert pkw.page_multiple(page) == offset // 2000


def test_page_index_covers_every_multiple() -> None:
    pages = {pkw.page_index(m) for m in range(64)}
    assert len(pages) == 64
    with pytest.raises(LocalProtocolError):
        pkw.page_index(64)


@pytest.mark.parametrize("layout", list(IndLayout))
@given(pnu=st.integers(0, 0xFFFF), sub=st.integers(0, 255))
def test_pke_ind_round_trip_with_page(layout: IndLayout, pnu: int, sub: int) -> None:
    pke, ind = pkw.encode_pke_ind(USS, layout, 6, pnu, sub)
    assert pke & 0x7FF < 2000
    assert pkw.decode_pke_ind(USS, layout, pke, ind) == (6, pnu, sub)


# ------------------------------------------------------- request tables


FC_REQUEST_TEXTS = {
    0: "No command",
    1: "Read parameter value",
    2: "Write parameter value in RAM (word)",
    3: "Write parameter value in RAM (double word)",
    13: "Write parameter value in RAM and EEprom (double word)",
    14: "Write parameter value in RAM and EEprom (word)",
    15: "Read/write text",
}
FC_RESPONSE_TEXTS = {
    0: "No response",
    1: "Parameter value transferred (word)",
    2: "Parameter value transferred (double word)",
    7: "Command cannot be performed",
    15: "text transferred",
}


@needs_seeds
def test_fc_tables_word_for_word_as_seed_000() -> None:
    with open(f"{SEEDS}/000_dc92febf75095d16.txt", encoding="utf-8") as seed:
        text = " ".join(seed.read().split())
    for ak, wording in FC_REQUEST_TEXTS.items():
        assert FC.requests[ak][1] == wording
        assert wording in text
    for ak, wording in FC_RESPONSE_TEXTS.items():
        assert FC.responses[ak][1] == wording
        assert wording in text


FC_FAULTS = {
    0: "The parameter number used does not exit",
    1: "There is no write access to the defined parameter",
    2: "Data value exceeds the parameter's limits",
    3: "The sub index used does not exit",
    4: "The parameter is not the array type",
    5: "The data type does not match the defined parameter",
    0x11: "Data change in the defined parameter is not possible in the frequency "
    "converter's present mode",
    0x82: "There is no bus access to the defined parameter",
    0x83: "Data change is not possible because factory setup is selected",
}


@pytest.mark.parametrize(("number", "text"), FC_FAULTS.items())
def test_fc_faults_as_in_seed(number: int, text: str) -> None:
    resp = pkw.decode_response(bytes([0x71, 0x55, 0, 0, 0, 0, 0, number]), FC, IndLayout.USS)
    assert isinstance(resp, pkw.Rejection)
    assert resp.fault == number
    assert resp.text.startswith(text)
    assert resp.pnu == 341


PCV_FAULTS_FROM_SEED = [*range(20), 130, 131]
HITACHI_FAULTS_FROM_SEED = [0, 1, 2, 3, 4, 5, 7, 9, 11, 17, 18, 102, 106]


@needs_seeds
@pytest.mark.parametrize(
    ("d", "seed", "numbers"),
    [
        (DANFOSS_PCV, "002_4fbd17853ec9f4af.txt", PCV_FAULTS_FROM_SEED),
        (HITACHI_SJPB, "004_6fa4fd8204bc6561.txt", HITACHI_FAULTS_FROM_SEED),
    ],
)
def test_fault_tables_follow_their_seed(d: Dialect, seed: str, numbers: list[int]) -> None:
    with open(f"{SEEDS}/{seed}", encoding="utf-8") as f:
        text = " ".join(f.read().split())
    assert sorted(d.faults) == numbers
    for fault in d.faults.values():
        assert fault.text in text, fault


@needs_seeds
def test_seed_request_and_response_texts_for_pcv_and_hitachi() -> None:
    for d, seed in (
        (DANFOSS_PCV, "002_4fbd17853ec9f4af.txt"),
        (HITACHI_SJPB, "004_6fa4fd8204bc6561.txt"),
    ):
        with open(f"{SEEDS}/{seed}", encoding="utf-8") as f:
            text = " ".join(f.read().split())
        for _, wording in d.requests.values():
            assert wording in text, wording
        for _, wording in d.responses.values():
            assert wording.split(" (including")[0] in text, wording


def test_unknown_fault_number_is_kept() -> None:
    resp = pkw.decode_response(bytes([0x70, 0x10, 0, 0, 0, 0, 0, 99]), USS, IndLayout.USS)
    assert isinstance(resp, pkw.Rejection)
    assert resp.fault == 99
    assert "99" in resp.text


def test_siemens_fault_numbers() -> None:
    expected = {0, 1, 2, 3, 4, 5, 6, 7, 11, 12, 17, 101, 102, 104, 106, 200, 201, 204}
    assert set(USS.faults) == expected
    assert USS.faults == PROFIDRIVE.faults


# Every request each dialect has, and what it must not have.
REQUESTS = {
    "fc": {0, 1, 2, 3, 4, 13, 14, 15},
    "uss": {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14, 15},
    "profidrive": {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14, 15},
    "danfoss-pcv": set(range(10)),
    "hitachi-sjpb": {0, 1, 2, 3, 6, 7, 9},
}
RESPONSES = {
    "fc": {0, 1, 2, 3, 7, 15},
    "uss": {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 15},
    "profidrive": {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 15},
    "danfoss-pcv": set(range(9)),
    "hitachi-sjpb": {0, 1, 2, 4, 6, 7, 8},
}


@pytest.mark.parametrize("name", list(DIALECTS))
def test_request_identifiers(name: str) -> None:
    d = dialect(name)
    assert set(d.requests) == REQUESTS[name]
    for ak in range(16):
        if ak in REQUESTS[name]:
            assert d.request_id(d.command(ak)) == ak or name == "fc"
        else:
            with pytest.raises(LocalProtocolError, match=f"no request identifier {ak}"):
                d.command(ak)


@pytest.mark.parametrize("name", list(DIALECTS))
def test_response_identifiers(name: str) -> None:
    d = dialect(name)
    assert set(d.responses) == RESPONSES[name]
    for ak in range(16):
        pkw_bytes = bytes([ak << 4 | 0x01, 0x00, 0, 0, 0, 0, 0, 1])
        if ak in RESPONSES[name]:
            pkw.decode_response(pkw_bytes, d, d.default_ind_layout)
        else:
            with pytest.raises(RemoteProtocolError, match=f"identifier {ak}"):
                pkw.decode_response(pkw_bytes, d, d.default_ind_layout)


@pytest.mark.parametrize(
    ("d", "command"),
    [
        (FC, Command.READ_ARRAY_COUNT),
        (FC, Command.WRITE_DESCRIPTION),
        (HITACHI_SJPB, Command.WRITE_ARRAY_DWORD),
        (HITACHI_SJPB, Command.READ_DESCRIPTION),
        (DANFOSS_PCV, Command.TEXT),
        (DANFOSS_PCV, Command.WRITE_WORD_EEPROM),
    ],
)
def test_requests_a_dialect_does_not_have(d: Dialect, command: Command) -> None:
    assert not d.has(command)
    with pytest.raises(LocalProtocolError, match=f"{d.name} dialect has no request"):
        pkw.request(d, command, 100)


def test_fc_has_no_ak_6_but_reads_arrays_with_ak_1() -> None:
    with pytest.raises(LocalProtocolError):
        FC.command(6)
    req = pkw.read(FC, 1530, 3)
    assert req.ak == 1
    pke, ind, _ = pke_ind(req, FC, IndLayout.USS)
    assert (pke, ind) == (0x1000 | 1530, 0x0003)


@pytest.mark.parametrize(
    ("width", "index", "store", "fc_ak", "uss_ak"),
    [
        (pkw.Width.WORD, None, pkw.Store.RAM, 2, 2),
        (pkw.Width.DWORD, None, pkw.Store.RAM, 3, 3),
        (pkw.Width.WORD, None, pkw.Store.EEPROM, 14, 14),
        (pkw.Width.DWORD, None, pkw.Store.EEPROM, 13, 13),
        (pkw.Width.WORD, 1, pkw.Store.RAM, 2, 7),
        (pkw.Width.DWORD, 1, pkw.Store.RAM, 3, 8),
        (pkw.Width.WORD, 1, pkw.Store.EEPROM, 14, 12),
        (pkw.Width.DWORD, 1, pkw.Store.EEPROM, 13, 11),
    ],
)
def test_write_identifiers(
    width: pkw.Width, index: int | None, store: pkw.Store, fc_ak: int, uss_ak: int
) -> None:
    assert pkw.write(FC, 341, 5, width, index=index, store=store).ak == fc_ak
    assert pkw.write(USS, 1082, 5, width, index=index, store=store).ak == uss_ak


def test_siemens_reads_use_6_with_an_index_and_1_without() -> None:
    assert pkw.read(USS, 21).ak == 1
    assert pkw.read(USS, 21, 0).ak == 6
    assert pkw.request(USS, Command.READ_ARRAY_COUNT, 947).ak == 9
    assert pkw.read_description(USS, 21, 6).ak == 4
    assert pkw.request(USS, Command.WRITE_DESCRIPTION, 21, subindex=6, value=0).ak == 5
    assert pkw.read_text(USS, 21).ak == 15
    assert pkw.none_request(USS).ak == 0


@pytest.mark.parametrize(
    ("d", "pnu"),
    [(FC, 4096), (USS, 65536), (PROFIDRIVE, 65536), (DANFOSS_PCV, 2048), (HITACHI_SJPB, 2048)],
)
def test_pnu_range_per_dialect(d: Dialect, pnu: int) -> None:
    with pytest.raises(LocalProtocolError, match="cannot be encoded"):
        pkw.read(d, pnu)
    pkw.read(d, pnu - 1)


def test_value_must_fit_the_request() -> None:
    with pytest.raises(LocalProtocolError):
        pkw.write(FC, 341, 0x10000, pkw.Width.WORD)
    with pytest.raises(LocalProtocolError):
        pkw.write(FC, 341, -1, pkw.Width.DWORD)
    with pytest.raises(LocalProtocolError, match="index 256"):
        pkw.read(USS, 21, 256)


def test_three_word_pkw_block_carries_only_words() -> None:
    word = pkw.write(USS, 1082, 5, pkw.Width.WORD)
    assert len(pkw.encode_request(word, USS, IndLayout.USS, 3)) == 6
    dword = pkw.write(USS, 1082, 5, pkw.Width.DWORD)
    with pytest.raises(LocalProtocolError, match="3 words"):
        pkw.encode_request(dword, USS, IndLayout.USS, 3)
    with pytest.raises(LocalProtocolError, match="no PKW"):
        pkw.encode_request(word, USS, IndLayout.USS, 0)


# ------------------------------------------------------------- FC text


def test_fc_text_read_and_write_mark_ind_high_byte() -> None:
    _, ind, _ = pke_ind(pkw.read_text(FC, 1540), FC, IndLayout.USS)
    assert ind >> 8 == 0x04
    req = pkw.write_text(FC, 1, b"ABC")
    data = pkw.encode_request(req, FC, IndLayout.USS, None)
    assert data == bytes([0xF0, 0x01, 0x05, 0x00]) + b"ABC"
    with pytest.raises(LocalProtocolError):
        pkw.encode_request(req, FC, IndLayout.USS, 4)
    with pytest.raises(LocalProtocolError):
        pkw.write_text(FC, 1, b"")


def test_fc_text_response_decodes() -> None:
    resp = pkw.decode_response(bytes([0xF6, 0x04, 0x04, 0x00]) + b"FC-302", FC, IndLayout.USS)
    assert isinstance(resp, pkw.TextResponse)
    assert (resp.pnu, resp.text) == (1540, b"FC-302")


# ------------------------------------------------------ response decoding


def test_value_width_follows_the_response_identifier() -> None:
    word = pkw.decode_response(bytes([0x16, 0x4E, 0, 0, 0, 0, 0x02, 0x0C]), FC, IndLayout.USS)
    assert word == pkw.ValueResponse(1, 1614, 0, 524, pkw.Width.WORD)
    dword = pkw.decode_response(bytes([0x26, 0x4D, 0, 0, 0, 1, 0x00, 0x02]), FC, IndLayout.USS)
    assert dword == pkw.ValueResponse(2, 1613, 0, 0x10002, pkw.Width.DWORD)


def test_siemens_float_value() -> None:
    resp = pkw.decode_response(bytes([0x24, 0x3A, 0, 0, 0x42, 0x48, 0, 0]), USS, IndLayout.USS)
    assert isinstance(resp, pkw.ValueResponse)
    assert (resp.pnu, resp.raw) == (1082, 0x42480000)


def test_no_change_rights_is_a_rejection_without_number() -> None:
    resp = pkw.decode_response(bytes([0x84, 0x3A, 0, 0, 0, 0, 0, 0]), USS, IndLayout.USS)
    assert isinstance(resp, pkw.Rejection)
    assert resp.fault is None
    resp = pkw.decode_response(
        bytes([0x84, 0x3A, 0, 0, 0, 0, 0, 0]), DANFOSS_PCV, IndLayout.PROFIDRIVE
    )
    assert isinstance(resp, pkw.Rejection)
    assert resp.text == "Not serviceable by PCV interface"


def test_other_responses() -> None:
    layout = IndLayout.USS
    assert isinstance(pkw.decode_response(bytes(8), USS, layout), pkw.NoResponse)
    count = pkw.decode_response(bytes([0x63, 0xB3, 0, 0, 0, 0, 0, 8]), USS, layout)
    assert count == pkw.ArrayCountResponse(6, 947, 0, 8)
    desc = pkw.decode_response(bytes([0x30, 0x15, 0, 6, 0, 0, 0, 3]), USS, layout)
    assert isinstance(desc, pkw.DescriptionResponse) and desc.subindex == 6
    spont = pkw.decode_response(bytes([0x90, 0x15, 0, 0, 0, 0, 0, 3]), USS, layout)
    assert isinstance(spont, pkw.SpontaneousResponse)


def test_short_or_inconsistent_pkw_is_the_peers_error() -> None:
    with pytest.raises(RemoteProtocolError):
        pkw.decode_response(b"\x10\x01", USS, IndLayout.USS)
    with pytest.raises(RemoteProtocolError, match="3 words"):
        pkw.decode_response(bytes([0x20, 0x01, 0, 0, 0, 1]), USS, IndLayout.USS)
    with pytest.raises(RemoteProtocolError):
        pkw.decode_response(bytes([0x10, 0x01, 0, 0, 1]), USS, IndLayout.USS)


# ------------------------------------------------------------- matching


def answer(
    req: pkw.PkwRequest,
    d: Dialect,
    ak: int,
    raw: int,
    *,
    pnu: int | None = None,
    sub: int | None = None,
) -> pkw.PkwResponse:
    data = bytearray(pkw.encode_request(req, d, d.default_ind_layout, 4))
    pke, ind = pkw.encode_pke_ind(
        d,
        d.default_ind_layout,
        ak,
        req.pnu if pnu is None else pnu,
        req.subindex if sub is None else sub,
    )
    data[:4] = pke.to_bytes(2, "big") + ind.to_bytes(2, "big")
    data[4:8] = raw.to_bytes(4, "big")
    return pkw.decode_response(bytes(data), d, d.default_ind_layout)


def test_matching_rule_for_reads() -> None:
    req = pkw.read(USS, 7841, 2)
    assert pkw.matches(req, answer(req, USS, 4, 5), USS)
    assert pkw.matches(req, answer(req, USS, 5, 5), USS)
    assert pkw.matches(req, answer(req, USS, 7, 0), USS)  # rejection answers too
    assert not pkw.matches(req, answer(req, USS, 0, 0), USS)  # AK 0: not yet
    assert not pkw.matches(req, answer(req, USS, 4, 5, pnu=1841), USS)  # page lost
    assert not pkw.matches(req, answer(req, USS, 4, 5, sub=3), USS)
    assert not pkw.matches(req, answer(req, USS, 6, 5), USS)  # count answers a 9


def test_matching_rule_for_changes_needs_the_echo() -> None:
    req = pkw.write(FC, 341, 1000, pkw.Width.DWORD)
    assert pkw.matches(req, answer(req, FC, 2, 1000), FC)
    assert not pkw.matches(req, answer(req, FC, 2, 999), FC)  # stale value
    assert not pkw.matches(req, answer(req, FC, 1, 1000), FC)  # word answer to a dword change
    assert pkw.matches(req, answer(req, FC, 7, 2), FC)
    word = pkw.write(USS, 1082, 7, pkw.Width.WORD)
    assert pkw.matches(word, answer(word, USS, 1, 7), USS)
    assert not pkw.matches(word, answer(word, USS, 2, 7), USS)


def test_the_none_request_matches_nothing() -> None:
    req = pkw.none_request(FC)
    assert not pkw.matches(req, answer(req, FC, 0, 0), FC)
    assert FC.accepts(0, 0) and not FC.accepts(0, 1)
    assert not FC.accepts(1, 9)


def test_unknown_dialect() -> None:
    with pytest.raises(LocalProtocolError, match="known: fc, uss"):
        dialect("modbus")


def test_reply_kinds_cover_the_tables() -> None:
    for d in DIALECTS.values():
        assert d.reply(7) is Reply.REJECTED


# ------------------------------------------------------------ round trips

commands = st.sampled_from(list(Command))


@given(
    name=st.sampled_from(list(DIALECTS)),
    layout=st.sampled_from(list(IndLayout)),
    command=commands,
    pnu=st.integers(0, 0xFFFF),
    sub=st.integers(0, 255),
    value=st.integers(0, 0xFFFFFFFF),
    pkw_words=st.sampled_from([3, 4]),
)
def test_request_round_trip(
    name: str, layout: IndLayout, command: Command, pnu: int, sub: int, value: int, pkw_words: int
) -> None:
    """Every request a dialect can say encodes and reads back (as its matching answer)."""
    d = dialect(name)
    if not d.has(command) or command in (Command.NONE, Command.TEXT) or pnu > d.max_pnu:
        with pytest.raises(LocalProtocolError):
            if command in (Command.NONE, Command.TEXT) and d.has(command) and pnu <= d.max_pnu:
                raise LocalProtocolError("skip")
            pkw.request(d, command, pnu, subindex=sub, value=value & 0xFFFF)
        return
    width_limit = 0xFFFFFFFF if command in pkw.DWORD_COMMANDS else 0xFFFF
    raw = value & width_limit
    req = pkw.request(d, command, pnu, subindex=sub, value=raw)
    if pkw_words == 3 and req.width is pkw.Width.DWORD:
        with pytest.raises(LocalProtocolError):
            pkw.encode_request(req, d, layout, pkw_words)
        return
    data = pkw.encode_request(req, d, layout, pkw_words)
    assert len(data) == 2 * pkw_words
    ak, back_pnu, back_sub = pkw.decode_pke_ind(
        d, layout, int.from_bytes(data[:2], "big"), int.from_bytes(data[2:4], "big")
    )
    assert (ak, back_pnu, back_sub) == (req.ak, pnu, sub)
    assert int.from_bytes(data[4:], "big") == raw


@given(
    name=st.sampled_from(list(DIALECTS)),
    layout=st.sampled_from(list(IndLayout)),
    ak=st.integers(0, 15),
    pnu=st.integers(0, 0xFFFF),
    sub=st.integers(0, 255),
    raw=st.integers(0, 0xFFFFFFFF),
)
def test_response_round_trip(
    name: str, layout: IndLayout, ak: int, pnu: int, sub: int, raw: int
) -> None:
    d = dialect(name)
    reply = d.reply(ak)
    if reply is None or reply is Reply.TEXT or pnu > d.max_pnu:
        return
    if reply in (Reply.WORD, Reply.ARRAY_WORD, Reply.ARRAY_COUNT, Reply.REJECTED):
        raw &= 0xFFFF
    if reply in (Reply.NONE, Reply.NO_RIGHTS):
        raw = 0  # these carry no value
    resp: pkw.PkwResponse = pkw.SpontaneousResponse(ak, pnu, sub, raw)
    data = pkw.encode_response(resp, d, layout, 4)
    decoded = pkw.decode_response(data, d, layout)
    assert (decoded.ak, decoded.pnu, decoded.subindex) == (ak, pnu, sub)
    assert pkw.encode_response(decoded, d, layout, 4) == data


@given(data=st.binary(max_size=40), name=st.sampled_from(list(DIALECTS)))
def test_decoding_raises_only_protocol_errors(data: bytes, name: str) -> None:
    d = dialect(name)
    with contextlib.suppress(RemoteProtocolError):
        pkw.decode_response(data, d, d.default_ind_layout)


def test_encode_response_text_and_short_blocks() -> None:
    text = pkw.TextResponse(15, 1540, 0, b"FC-302")
    data = pkw.encode_response(text, FC, IndLayout.USS, None)
    assert data == bytes([0xF6, 0x04, 0x04, 0x00]) + b"FC-302"
    count = pkw.ArrayCountResponse(6, 947, 0, 8)
    assert pkw.encode_response(count, USS, IndLayout.USS, 3)[-2:] == b"\x00\x08"
    rej = pkw.Rejection(7, 21, 0, 1, "read only", "read only")
    assert pkw.encode_response(rej, USS, IndLayout.USS, 4)[-4:] == b"\x00\x00\x00\x01"
    big = pkw.ValueResponse(2, 21, 0, 0x10000, pkw.Width.DWORD)
    with pytest.raises(LocalProtocolError):
        pkw.encode_response(big, USS, IndLayout.USS, 3)


def test_every_rejection_a_dialect_can_carry() -> None:
    """The fault numbers of the dialect's table, and "no change rights" (no number)
    where the dialect has that answer (USS, PROFIdrive, PCV, Hitachi: AK 8; FC has none)."""
    uss = pkw.rejections(USS)
    assert (0, "illegal parameter number") in uss and (2, "limit exceeded") in uss
    assert (None, pkw.NO_CHANGE_RIGHTS) in uss
    assert len(uss) == len(USS.faults) + 1
    fc = pkw.rejections(FC)
    assert all(number is not None for number, _ in fc) and len(fc) == len(FC.faults)
    for d in (PROFIDRIVE, DANFOSS_PCV, HITACHI_SJPB):
        assert (None, pkw.NO_CHANGE_RIGHTS) in pkw.rejections(d)


def test_ak_0_in_a_variable_block_is_pke_and_ind_alone() -> None:
    """USS specification, part C, 4.1.2: AK 0 carries no PWE with a variable length; a
    fixed block is filled with zeros."""
    idle = pkw.NoResponse(0, 0, 0)
    assert pkw.encode_response(idle, USS, IndLayout.USS, None) == bytes(4)
    assert pkw.encode_response(idle, USS, IndLayout.USS, 4) == bytes(8)
    assert pkw.encode_response(idle, USS, IndLayout.USS, 3) == bytes(6)


def test_judge_tells_an_answer_a_wait_and_a_change_acknowledged_with_another_value() -> None:
    """SINAMICS G120 CU240B-2/CU240E-2 Operating Instructions, 6.3: the answer to a change
    echoes the value in PWE. An acknowledgement (AK 2) of the parameter with another value
    means the drive took something else: a mismatch, never "not yet" (a repeat would write
    it again)."""
    fifty, forty = 0x42480000, 0x42200000  # 50.0 and 40.0 as f32
    change = pkw.write(USS, 1082, fifty, pkw.Width.DWORD)  # AK 3
    echo = pkw.ValueResponse(2, 1082, 0, fifty, pkw.Width.DWORD)
    assert pkw.judge(change, echo, USS) is pkw.Verdict.ANSWER
    other = pkw.ValueResponse(2, 1082, 0, forty, pkw.Width.DWORD)
    assert pkw.judge(change, other, USS) is pkw.Verdict.MISMATCH
    refused = pkw.Rejection(7, 1082, 0, 2, "Lower or upper value limit exceeded", "limit")
    assert pkw.judge(change, refused, USS) is pkw.Verdict.ANSWER
    for not_yet in (
        pkw.ValueResponse(2, 1083, 0, fifty, pkw.Width.DWORD),  # another parameter's
        pkw.NoResponse(0, 0, 0),  # AK 0
    ):
        assert pkw.judge(change, not_yet, USS) is pkw.Verdict.NOT_YET
    # a read has no value of its own to compare: any value of its parameter answers it
    read = pkw.read(USS, 1082)
    assert pkw.judge(read, other, USS) is pkw.Verdict.ANSWER
