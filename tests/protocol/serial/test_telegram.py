"""Framing: the example telegrams of protocol.md section 7, ADR formats, BCC, block shapes."""

from __future__ import annotations

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import FC, USS, IndLayout
from pkwbus.protocol.serial.telegram import (
    FC_PARAMETER,
    FC_PROCESS,
    Address,
    BlockShape,
    FcAddressFormat,
    Telegram,
    bcc,
    decode_fc_adr,
    decode_uss_adr,
    encode_block,
    fc_adr,
    fc_lengths,
    frame,
    split_block,
    uss_adr,
    uss_lengths,
)


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text)


def test_fc_process_only_request() -> None:
    adr = fc_adr(4, FcAddressFormat.RANGE_1_31)
    wire = frame(adr, encode_block(b"", [0x047C, 0x2000]))
    assert wire == hexbytes("02 06 04 04 7C 20 00 58")


def test_fc_process_only_response() -> None:
    block = split_block(hexbytes("06 07 00 00"), FC_PROCESS)
    assert block.pzd == (0x0607, 0x0000)
    assert frame(0x04, encode_block(b"", block.pzd)) == hexbytes("02 06 04 06 07 00 00 01")


@pytest.mark.parametrize(
    ("make", "expected"),
    [
        (lambda: pkw.read(FC, 1614), "02 0E 01 16 4E 00 00 00 00 00 00 00 00 00 00 55"),
        (
            lambda: pkw.write(FC, 414, 1000, pkw.Width.WORD, store=pkw.Store.EEPROM),
            "02 0E 01 E1 9E 00 00 00 00 03 E8 00 00 00 00 99",
        ),
        (lambda: pkw.read(FC, 341), "02 0E 01 11 55 00 00 00 00 00 00 00 00 00 00 49"),
    ],
)
def test_fc_parameter_telegrams(make: object, expected: str) -> None:
    req = make()  # type: ignore[operator]
    data = pkw.encode_request(req, FC, IndLayout.USS, 4)
    # ADR 0x01 as in the manual's examples (1-31 format).
    wire = frame(fc_adr(1, FcAddressFormat.RANGE_1_31), encode_block(data, [0, 0]))
    assert wire == hexbytes(expected)


def test_uss_broadcast_process_telegram() -> None:
    data = encode_block(b"\x00" * 6, [0x047E, 0x0000])
    wire = frame(uss_adr(0), data)
    assert wire == hexbytes("02 0C 00 00 00 00 00 00 00 04 7E 00 00 74")


def test_uss_read_with_three_pkw_words() -> None:
    req = pkw.request(USS, USS.command(1), 0x066, subindex=1)
    data = pkw.encode_request(req, USS, IndLayout.USS, 3)
    wire = frame(uss_adr(3), encode_block(data, [0, 0]))
    assert wire == hexbytes("02 0C 03 10 66 00 01 00 00 00 00 00 00 7A")


def test_bcc_of_a_whole_telegram_is_zero() -> None:
    wire = hexbytes("02 0E 01 16 4E 00 00 00 00 00 00 00 00 00 00 55")
    assert bcc(wire) == 0
    assert bcc(wire[:-1]) == 0x55


def test_telegram_encode_equals_frame() -> None:
    assert Telegram(0x81, b"\x00\x01").encode() == frame(0x81, b"\x00\x01")


def test_frame_refuses_oversized_telegrams_and_bad_adr() -> None:
    with pytest.raises(LocalProtocolError):
        frame(1, bytes(253))
    with pytest.raises(LocalProtocolError):
        frame(256, b"")
    assert len(frame(1, bytes(252))) == 256


@pytest.mark.parametrize(
    ("address", "fmt", "broadcast", "adr"),
    [
        (1, FcAddressFormat.RANGE_1_126, False, 0x81),
        (126, FcAddressFormat.RANGE_1_126, False, 0xFE),
        (0, FcAddressFormat.RANGE_1_126, True, 0x80),
        (31, FcAddressFormat.RANGE_1_31, False, 0x1F),
        (0, FcAddressFormat.RANGE_1_31, True, 0x20),
    ],
)
def test_fc_address_formats(address: int, fmt: FcAddressFormat, broadcast: bool, adr: int) -> None:
    assert fc_adr(address, fmt, broadcast=broadcast) == adr
    decoded = decode_fc_adr(adr)
    assert decoded.broadcast is broadcast
    if not broadcast:
        assert decoded.address == address


def test_fc_1_31_broadcast_ignores_address_bits() -> None:
    assert decode_fc_adr(0x20 | 0x07) == Address(7, broadcast=True)


@pytest.mark.parametrize("address", [0, 127, -1])
def test_fc_1_126_address_range(address: int) -> None:
    with pytest.raises(LocalProtocolError, match="1-126"):
        fc_adr(address)


def test_fc_1_31_address_range() -> None:
    with pytest.raises(LocalProtocolError, match="1-31"):
        fc_adr(32, FcAddressFormat.RANGE_1_31)


def test_uss_address_bits() -> None:
    assert uss_adr(5, mirror=True) == 0x45
    assert uss_adr(0, broadcast=True) == 0x20
    assert decode_uss_adr(0x45) == Address(5, mirror=True)
    assert decode_uss_adr(0xA3) == Address(3, broadcast=True, special=True)
    with pytest.raises(LocalProtocolError):
        uss_adr(32)


def test_block_shapes() -> None:
    assert FC_PARAMETER.lge == 14
    assert FC_PROCESS.lge == 6
    assert BlockShape(4, 2).lge == 14
    assert BlockShape(3, 2).lge == 12
    assert BlockShape(None, 2).lge is None
    assert BlockShape(0, 16).lge == 34
    with pytest.raises(LocalProtocolError):
        BlockShape(5, 2)
    with pytest.raises(LocalProtocolError):
        BlockShape(4, 17)


def test_split_block_checks_the_length() -> None:
    with pytest.raises(RemoteProtocolError):
        split_block(bytes(10), FC_PARAMETER)
    with pytest.raises(RemoteProtocolError):
        split_block(bytes(2), BlockShape(None, 2))
    block = split_block(bytes(range(7)) + b"\x12\x34\x56\x78", BlockShape(None, 2))
    assert block.pkw == bytes(range(7))
    assert block.pzd == (0x1234, 0x5678)


def test_encode_block_refuses_words_over_16_bits() -> None:
    with pytest.raises(LocalProtocolError):
        encode_block(b"", [0x10000])


def test_lengths() -> None:
    assert 6 in fc_lengths() and 14 in fc_lengths() and 8 not in fc_lengths()
    assert uss_lengths([BlockShape(4, 2)]) == frozenset({14})
    assert uss_lengths([BlockShape(None, 2)]) == frozenset(range(2, 255, 2))


def test_decode_adr_by_protocol() -> None:
    from pkwbus.protocol.buses import Bus, decode_adr

    assert decode_adr(Bus.FC, 0x81) == Address(1)
    assert decode_adr(Bus.USS, 0x41) == Address(1, mirror=True)
