"""Telegram framing shared by the Danfoss FC and Siemens USS protocols.

A telegram is ``STX LGE ADR data... BCC``: STX is 0x02, LGE counts the bytes
after itself (data + ADR + BCC), BCC is the XOR of every byte before it.
Words travel high byte first. This module is pure: bytes in, objects out.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for a telegram that cannot be
built and :class:`~pkwbus.protocol.errors.RemoteProtocolError` for received bytes that
do not decode.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError

__all__ = [
    "FC_BROADCAST_1_31",
    "FC_FORMAT_1_126",
    "FC_PARAMETER",
    "FC_PROCESS",
    "MAX_LGE",
    "MAX_TELEGRAM",
    "PCD_WORDS_FC",
    "STX",
    "USS_BROADCAST",
    "USS_DEFAULT",
    "USS_MIRROR",
    "USS_SPECIAL",
    "Address",
    "BadChecksum",
    "BadLength",
    "Block",
    "BlockShape",
    "Deframer",
    "DeframerEvent",
    "FcAddressFormat",
    "FramingError",
    "Skipped",
    "Telegram",
    "Truncated",
    "bcc",
    "decode_fc_adr",
    "decode_uss_adr",
    "encode_block",
    "fc_adr",
    "fc_lengths",
    "frame",
    "split_block",
    "uss_adr",
    "uss_lengths",
]

STX: Final = 0x02
MAX_TELEGRAM: Final = 256  # bytes, STX to BCC
MAX_LGE: Final = MAX_TELEGRAM - 2
PCD_WORDS_FC: Final = 2


def bcc(data: bytes | bytearray | memoryview) -> int:
    """XOR of every byte, starting from 0."""
    acc = 0
    for byte in data:
        acc ^= byte
    return acc


@dataclass(frozen=True, slots=True)
class Telegram:
    """One telegram: the ADR byte as on the wire and the data between ADR and BCC."""

    adr: int
    data: bytes

    def encode(self) -> bytes:
        return frame(self.adr, self.data)


def frame(adr: int, data: bytes) -> bytes:
    """Wrap ``data`` into ``STX LGE ADR data BCC``."""
    if not 0 <= adr <= 0xFF:
        raise LocalProtocolError(f"ADR byte {adr} is not a byte")
    lge = len(data) + 2
    if lge > MAX_LGE:
        raise LocalProtocolError(f"telegram of {lge + 2} bytes exceeds {MAX_TELEGRAM}")
    head = bytes((STX, lge, adr)) + data
    return head + bytes((bcc(head),))


# --------------------------------------------------------------------------- ADR


class FcAddressFormat(enum.StrEnum):
    """The two ADR formats of the FC protocol (Danfoss FC 102 manual, telegram structure)."""

    RANGE_1_31 = "1-31"
    RANGE_1_126 = "1-126"


FC_BROADCAST_1_31: Final = 0x20
FC_FORMAT_1_126: Final = 0x80
USS_BROADCAST: Final = 0x20
USS_MIRROR: Final = 0x40
USS_SPECIAL: Final = 0x80


@dataclass(frozen=True, slots=True)
class Address:
    """A decoded ADR byte."""

    address: int
    broadcast: bool = False
    mirror: bool = False
    special: bool = False


def fc_adr(
    address: int,
    fmt: FcAddressFormat = FcAddressFormat.RANGE_1_126,
    *,
    broadcast: bool = False,
) -> int:
    """The FC ADR byte for a follower address, or for a broadcast."""
    if fmt is FcAddressFormat.RANGE_1_126:
        if broadcast:
            return FC_FORMAT_1_126
        if not 1 <= address <= 126:
            raise LocalProtocolError(f"FC address {address} is outside 1-126")
        return FC_FORMAT_1_126 | address
    if broadcast:
        return FC_BROADCAST_1_31
    if not 1 <= address <= 31:
        raise LocalProtocolError(f"FC address {address} is outside 1-31 (1-31 format)")
    return address


def decode_fc_adr(adr: int) -> Address:
    if adr & FC_FORMAT_1_126:
        address = adr & 0x7F
        return Address(address, broadcast=address == 0)
    if adr & FC_BROADCAST_1_31:
        return Address(adr & 0x1F, broadcast=True)
    return Address(adr & 0x1F)


def uss_adr(address: int, *, broadcast: bool = False, mirror: bool = False) -> int:
    """The USS ADR byte: bits 0-4 address, bit 5 broadcast, bit 6 mirror."""
    if not 0 <= address <= 31:
        raise LocalProtocolError(f"USS address {address} is outside 0-31")
    return address | (USS_BROADCAST if broadcast else 0) | (USS_MIRROR if mirror else 0)


def decode_uss_adr(adr: int) -> Address:
    return Address(
        adr & 0x1F,
        broadcast=bool(adr & USS_BROADCAST),
        mirror=bool(adr & USS_MIRROR),
        special=bool(adr & USS_SPECIAL),
    )


# ---------------------------------------------------------------- data blocks


@dataclass(frozen=True, slots=True)
class BlockShape:
    """How a telegram's data splits into PKW and PZD.

    ``pkw_words`` is 0, 3 or 4 for a fixed PKW part, or None for a variable
    part (USS PKW length 127, FC text block). ``pzd_words`` is the number of
    process data words at the end (FC: always 2, PCD1 and PCD2).
    """

    pkw_words: int | None
    pzd_words: int

    def __post_init__(self) -> None:
        if self.pkw_words is not None and self.pkw_words not in (0, 3, 4):
            raise LocalProtocolError(f"PKW length {self.pkw_words} is not 0, 3, 4 or variable")
        if not 0 <= self.pzd_words <= 16:
            raise LocalProtocolError(f"PZD length {self.pzd_words} is outside 0-16")

    @property
    def lge(self) -> int | None:
        """LGE of a telegram of this shape, None when the PKW part is variable."""
        if self.pkw_words is None:
            return None
        return 2 * (self.pkw_words + self.pzd_words) + 2


FC_PROCESS = BlockShape(0, PCD_WORDS_FC)
FC_PARAMETER = BlockShape(4, PCD_WORDS_FC)
USS_DEFAULT = BlockShape(4, 2)


@dataclass(frozen=True, slots=True)
class Block:
    """A telegram's data, split: the PKW bytes and the PZD words."""

    pkw: bytes
    pzd: tuple[int, ...]

    @property
    def status_word(self) -> int | None:
        """A reply's status word: its first process data word; None without PZD."""
        return self.pzd[0] if self.pzd else None

    @property
    def main_actual(self) -> int | None:
        """A reply's main actual value: its second process data word (FC protocol PCD 2,
        USS PZD2 "HIW"); None with fewer than two PZD words."""
        return self.pzd[1] if len(self.pzd) >= 2 else None


def encode_block(pkw: bytes, pzd: Sequence[int]) -> bytes:
    out = bytearray(pkw)
    for word in pzd:
        if not 0 <= word <= 0xFFFF:
            raise LocalProtocolError(f"process data word {word} is not 16 bits")
        out += word.to_bytes(2, "big")
    return bytes(out)


def split_block(data: bytes, shape: BlockShape) -> Block:
    """Split telegram data by ``shape``; a length that does not fit is the peer's error."""
    pzd_len = 2 * shape.pzd_words
    if shape.pkw_words is not None and len(data) != 2 * shape.pkw_words + pzd_len:
        raise RemoteProtocolError(
            f"telegram has {len(data)} data bytes, expected {2 * shape.pkw_words + pzd_len}"
        )
    if len(data) < pzd_len:
        raise RemoteProtocolError(f"telegram has {len(data)} data bytes, fewer than its PZD")
    cut = len(data) - pzd_len
    return Block(data[:cut], _PZD[shape.pzd_words].unpack_from(data, cut))


_PZD = tuple(struct.Struct(f">{n}H") for n in range(17))  # 0-16 words, high byte first


def fc_lengths() -> frozenset[int]:
    """LGE values an FC telegram may have: process block, parameter block, text block."""
    return frozenset({FC_PROCESS.lge or 0} | set(range(10, MAX_LGE + 1)))


def uss_lengths(shapes: Iterable[BlockShape] = ()) -> frozenset[int]:
    """LGE values of USS telegrams: those of ``shapes``, or every even length when none given."""
    fixed = {s.lge for s in shapes}
    if fixed and None not in fixed:
        return frozenset(x for x in fixed if x is not None)
    return frozenset(range(2, MAX_LGE + 1, 2))


# ------------------------------------------------------------------ deframer


@dataclass(frozen=True, slots=True)
class FramingError:
    """Base of the deframer's error events: something on the line was not a telegram."""


@dataclass(frozen=True, slots=True)
class Skipped(FramingError):
    """Bytes passed over while hunting for STX."""

    count: int


@dataclass(frozen=True, slots=True)
class BadLength(FramingError):
    """An STX followed by an LGE that no telegram of this protocol has."""

    lge: int


@dataclass(frozen=True, slots=True)
class BadChecksum(FramingError):
    """A telegram whose BCC does not match its bytes."""

    raw: bytes


@dataclass(frozen=True, slots=True)
class Truncated(FramingError):
    """A telegram that stopped before its LGE said it would (seen at a line gap)."""

    raw: bytes


DeframerEvent = Telegram | FramingError


class Deframer:
    """Streaming deframer: feed it chunks, get telegrams and error events in order.

    It hunts for STX, checks LGE against ``lengths`` and the BCC, and after a
    bad candidate resumes the hunt one byte after that candidate's STX, so a
    valid telegram that follows garbage, a truncated telegram or a bad BCC is
    found. Bytes that follow an error up to the next valid telegram are
    reported once, as skipped, not as a string of errors. ``flush`` marks a
    gap on the line: an incomplete telegram then is truncated. The buffer
    never holds more than one incomplete telegram (at most 256 bytes).
    """

    __slots__ = ("_buf", "_hunting", "_lengths")

    def __init__(self, lengths: frozenset[int]) -> None:
        self._lengths = lengths
        self._buf = bytearray()
        self._hunting = False

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, chunk: bytes) -> list[DeframerEvent]:
        self._buf += chunk
        return self._parse(final=False)

    def flush(self) -> list[DeframerEvent]:
        """A gap on the line: nothing buffered can grow into a telegram any more."""
        return self._parse(final=True)

    def reset(self) -> None:
        self._buf.clear()
        self._hunting = False

    def _parse(self, *, final: bool) -> list[DeframerEvent]:
        buf = self._buf
        out: list[DeframerEvent] = []
        size = len(buf)
        pos = 0
        skipped = 0
        while pos < size:
            stx = buf.find(STX, pos)
            if stx < 0:
                skipped += size - pos
                pos = size
                break
            skipped += stx - pos
            pos = stx
            event = self._candidate(buf, pos, size, final=final)
            if event is None:  # incomplete, wait for more bytes
                break
            if isinstance(event, Telegram):
                if skipped:
                    out.append(Skipped(skipped))
                    skipped = 0
                out.append(event)
                pos += len(event.data) + 4
                self._hunting = False
                continue
            if self._hunting:
                skipped += 1
            else:
                if skipped:
                    out.append(Skipped(skipped))
                    skipped = 0
                out.append(event)
                self._hunting = True
            pos += 1
        if skipped:
            out.append(Skipped(skipped))
        del buf[:pos]
        return out

    def _candidate(
        self, buf: bytearray, pos: int, size: int, *, final: bool
    ) -> DeframerEvent | None:
        """Judge the candidate telegram whose STX is at ``pos``; None while incomplete."""
        if size - pos < 2:
            return Truncated(bytes(buf[pos:])) if final else None
        lge = buf[pos + 1]
        if lge not in self._lengths:
            return BadLength(lge)
        end = pos + lge + 2
        if end > size:
            return Truncated(bytes(buf[pos:])) if final else None
        acc = 0
        for byte in buf[pos:end]:
            acc ^= byte
        if acc:
            return BadChecksum(bytes(buf[pos:end]))
        return Telegram(buf[pos + 2], bytes(buf[pos + 3 : end - 1]))
