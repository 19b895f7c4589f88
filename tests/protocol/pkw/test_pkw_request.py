"""The follower's side of the PKW channel: decoding requests, choosing response identifiers."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import DIALECTS, FC, HITACHI_SJPB, USS, Command, IndLayout, Reply
from pkwbus.protocol.pkw.dialects import dialect as get_dialect

NUMERIC = [c for c in Command if c not in (Command.NONE, Command.TEXT)]


@given(
    name=st.sampled_from(list(DIALECTS)),
    layout=st.sampled_from(list(IndLayout)),
    command=st.sampled_from(NUMERIC),
    pnu=st.integers(0, 0xFFFF),
    sub=st.integers(0, 255),
    value=st.integers(0, 0xFFFFFFFF),
    pkw_words=st.sampled_from([3, 4]),
)
def test_decode_request_inverts_encode_request(
    name: str, layout: IndLayout, command: Command, pnu: int, sub: int, value: int, pkw_words: int
) -> None:
    d = get_dialect(name)
    if not d.has(command) or pnu > d.max_pnu:
        return
    dword = command in pkw.DWORD_COMMANDS
    if pkw_words == 3 and dword:
        return
    raw = value & (0xFFFFFFFF if dword else 0xFFFF)
    req = pkw.request(d, command, pnu, subindex=sub, value=raw)
    back = pkw.decode_request(pkw.encode_request(req, d, layout, pkw_words), d, layout)
    assert back.command is d.command(req.ak)
    assert (back.ak, back.pnu, back.subindex, back.value, back.text) == (
        req.ak,
        pnu,
        sub,
        raw,
        b"",
    )


def test_fc_text_requests_read_and_write() -> None:
    layout = FC.default_ind_layout
    read = pkw.decode_request(
        pkw.encode_request(pkw.read_text(FC, 1540), FC, layout, 4), FC, layout
    )
    assert (read.command, read.pnu, read.text) == (Command.TEXT, 1540, b"")
    req = pkw.write_text(FC, 1540, b"PUMP 3")
    write = pkw.decode_request(pkw.encode_request(req, FC, layout, None), FC, layout)
    assert (write.command, write.pnu, write.text) == (Command.TEXT, 1540, b"PUMP 3")


def test_text_write_in_a_dialect_without_markers() -> None:
    req = pkw.write_text(USS, 199, b"ABC")
    back = pkw.decode_request(pkw.encode_request(req, USS, IndLayout.USS, None), USS, IndLayout.USS)
    assert back.text == b"ABC"


def test_word_request_takes_pwe_low() -> None:
    data = bytes([0x20, 0x55, 0x00, 0x00, 0x12, 0x34, 0x03, 0xE8])  # write word, PWE high junk
    assert pkw.decode_request(data, FC, IndLayout.USS).value == 1000


def test_unknown_request_identifier_is_the_peers_error() -> None:
    data = bytes([0x50, 0x01, 0, 0, 0, 0, 0, 0])  # AK 5 is not an FC request
    with pytest.raises(RemoteProtocolError):
        pkw.decode_request(data, FC, IndLayout.USS)
    with pytest.raises(RemoteProtocolError):
        pkw.decode_request(b"\x10\x01", FC, IndLayout.USS)


@given(data=st.binary(max_size=40), name=st.sampled_from(list(DIALECTS)))
def test_decode_request_raises_only_remote_errors(data: bytes, name: str) -> None:
    d = get_dialect(name)
    with contextlib.suppress(RemoteProtocolError):
        pkw.decode_request(data, d, d.default_ind_layout)


@pytest.mark.parametrize(
    ("name", "reply", "ak"),
    [
        ("fc", Reply.WORD, 1),
        ("fc", Reply.ARRAY_WORD, 1),
        ("fc", Reply.ARRAY_DWORD, 2),
        ("fc", Reply.REJECTED, 7),
        ("fc", Reply.TEXT, 15),
        ("uss", Reply.ARRAY_WORD, 4),
        ("uss", Reply.ARRAY_DWORD, 5),
        ("uss", Reply.ARRAY_COUNT, 6),
        ("hitachi-sjpb", Reply.ARRAY_DWORD, 2),
    ],
)
def test_response_id(name: str, reply: Reply, ak: int) -> None:
    d = get_dialect(name)
    assert pkw.response_id(d, reply) == ak
    assert d.reply(ak) in (reply, Reply.WORD, Reply.DWORD)


def test_response_id_for_a_reply_the_dialect_lacks() -> None:
    with pytest.raises(LocalProtocolError):
        pkw.response_id(HITACHI_SJPB, Reply.TEXT)


def test_a_parameter_is_read_by_its_value_or_its_text() -> None:
    """A text parameter is read with AK 15 (USS: "request text"), any other by its value."""
    assert pkw.read_parameter(USS, 1082, None, text=False) == pkw.read(USS, 1082)
    assert pkw.read_parameter(USS, 947, 3, text=False) == pkw.read(USS, 947, 3)
    text = pkw.read_parameter(USS, 199, None, text=True)
    assert text == pkw.read_text(USS, 199, 0)
    assert (text.ak, text.command, text.subindex) == (15, Command.TEXT, 0)
    assert pkw.read_parameter(USS, 199, 2, text=True).subindex == 2


def test_a_variable_read_without_pwe_is_a_read() -> None:
    """With a variable length a read needs no PWE: PKE and IND alone ask for the value
    (the follower ignores PWE when a value is requested, MICROMASTER 420 Reference
    Manual, 3.3.5)."""
    req = pkw.decode_request(bytes.fromhex("143A 0000"), USS, IndLayout.USS, None)
    assert req == pkw.PkwRequest(1, Command.READ, 1082, 0, 0)
    # a change needs its value: without PWE it is the peer's error
    with pytest.raises(RemoteProtocolError):
        pkw.decode_request(bytes.fromhex("243A 0000"), USS, IndLayout.USS, None)
