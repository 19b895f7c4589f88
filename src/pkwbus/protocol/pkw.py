"""The PKW parameter channel: PKE, IND and PWE, requests and responses.

Requests are built for a dialect (which request identifiers it has, how wide
its PNU is, whether it has a page index) and an IND layout; responses are
decoded with the same two, and :func:`matches` applies the rule of the
SINAMICS G120 CU240B-2/CU240E-2 Operating Instructions, section 6.3: the
response identifier fits, PNU and IND are the request's, and a change is
echoed in PWE.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from pkwbus.protocol.dialects import (
    DWORD_COMMANDS,
    WRITE_COMMANDS,
    Command,
    Dialect,
    IndLayout,
    Reply,
)
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError

__all__ = [
    "NO_CHANGE_RIGHTS",
    "PAGE_SIZE",
    "ArrayCountResponse",
    "DescriptionResponse",
    "NoResponse",
    "PkwRequest",
    "PkwResponse",
    "Rejection",
    "SpontaneousResponse",
    "Store",
    "TextResponse",
    "ValueResponse",
    "Width",
    "decode_pke_ind",
    "decode_request",
    "decode_response",
    "encode_pke_ind",
    "encode_request",
    "encode_response",
    "matches",
    "none_request",
    "page_index",
    "page_multiple",
    "read",
    "read_description",
    "read_parameter",
    "read_text",
    "rejections",
    "request",
    "response_id",
    "write",
    "write_text",
]

PAGE_SIZE = 2000
_PNU_MASK_11 = 0x7FF
# Bits of the page index byte for a + 2b + 4c + 8d + 16e + 32f (SINAMICS CU240S
# operating instructions, USS page index).
_PAGE_BITS = (0x80, 0x10, 0x20, 0x40, 0x04, 0x08)


class Width(enum.Enum):
    WORD = 16
    DWORD = 32


class Store(enum.StrEnum):
    RAM = "ram"
    EEPROM = "eeprom"


def page_index(multiple: int) -> int:
    """The page index byte for a PNU offset of ``multiple`` * 2000."""
    if not 0 <= multiple < 64:
        raise LocalProtocolError(f"page offset {multiple * PAGE_SIZE} cannot be encoded")
    return sum(bit for n, bit in enumerate(_PAGE_BITS) if multiple >> n & 1)


def page_multiple(page: int) -> int:
    """Inverse of :func:`page_index`: the multiple of 2000 a page index byte stands for."""
    return sum(1 << n for n, bit in enumerate(_PAGE_BITS) if page & bit)


@dataclass(frozen=True, slots=True)
class PkwRequest:
    """One PKW request. ``value`` is PWE as an unsigned number (a word in its low 16 bits)."""

    ak: int
    command: Command
    pnu: int
    subindex: int = 0
    value: int = 0
    text: bytes = b""

    @property
    def is_write(self) -> bool:
        return self.command in WRITE_COMMANDS

    @property
    def width(self) -> Width:
        return Width.DWORD if self.command in DWORD_COMMANDS else Width.WORD


def _check_subindex(subindex: int) -> None:
    if not 0 <= subindex <= 0xFF:
        raise LocalProtocolError(f"index {subindex} is outside 0-255")


def request(
    dialect: Dialect,
    command: Command,
    pnu: int,
    *,
    subindex: int = 0,
    value: int = 0,
    text: bytes = b"",
) -> PkwRequest:
    """A request for ``command``; a clear error for what the dialect cannot say."""
    dialect.check_pnu(pnu)
    _check_subindex(subindex)
    limit = 0xFFFFFFFF if command in DWORD_COMMANDS else 0xFFFF
    if not 0 <= value <= limit:
        raise LocalProtocolError(f"raw value {value} does not fit the {command.value} request")
    return PkwRequest(dialect.request_id(command), command, pnu, subindex, value, text)


def read(dialect: Dialect, pnu: int, index: int | None = None) -> PkwRequest:
    """Read a value; with an index, an array element (AK 6 where the dialect has it)."""
    command = Command.READ if index is None else Command.READ_ARRAY
    return request(dialect, command, pnu, subindex=index or 0)


def write(
    dialect: Dialect,
    pnu: int,
    raw: int,
    width: Width,
    *,
    index: int | None = None,
    store: Store = Store.RAM,
) -> PkwRequest:
    """Change a value in RAM or in RAM and EEPROM, as a word or a double word."""
    command = _WRITE_COMMAND[(width, index is not None, store)]
    return request(dialect, command, pnu, subindex=index or 0, value=raw)


_WRITE_COMMAND = {
    (Width.WORD, False, Store.RAM): Command.WRITE_WORD,
    (Width.DWORD, False, Store.RAM): Command.WRITE_DWORD,
    (Width.WORD, True, Store.RAM): Command.WRITE_ARRAY_WORD,
    (Width.DWORD, True, Store.RAM): Command.WRITE_ARRAY_DWORD,
    (Width.WORD, False, Store.EEPROM): Command.WRITE_WORD_EEPROM,
    (Width.DWORD, False, Store.EEPROM): Command.WRITE_DWORD_EEPROM,
    (Width.WORD, True, Store.EEPROM): Command.WRITE_ARRAY_WORD_EEPROM,
    (Width.DWORD, True, Store.EEPROM): Command.WRITE_ARRAY_DWORD_EEPROM,
}


def read_description(dialect: Dialect, pnu: int, element: int) -> PkwRequest:
    return request(dialect, Command.READ_DESCRIPTION, pnu, subindex=element)


def read_text(dialect: Dialect, pnu: int, index: int = 0) -> PkwRequest:
    return request(dialect, Command.TEXT, pnu, subindex=index)


def read_parameter(dialect: Dialect, pnu: int, index: int | None, *, text: bool) -> PkwRequest:
    """The read of one parameter: its text (AK 15) for a text parameter, else its value."""
    if text:
        return read_text(dialect, pnu, index or 0)
    return read(dialect, pnu, index)


def write_text(dialect: Dialect, pnu: int, text: bytes, index: int = 0) -> PkwRequest:
    if not text:
        raise LocalProtocolError("a text write needs at least one character")
    return request(dialect, Command.TEXT, pnu, subindex=index, text=text)


def none_request(dialect: Dialect) -> PkwRequest:
    """AK 0: what a master sends when no parameter job is pending."""
    return PkwRequest(dialect.request_id(Command.NONE), Command.NONE, 0)


# ------------------------------------------------------------- PKE and IND


def encode_pke_ind(
    dialect: Dialect, layout: IndLayout, ak: int, pnu: int, subindex: int, high: int = 0
) -> tuple[int, int]:
    """PKE and IND words for ``pnu`` and ``subindex`` (``high``: FC text marker)."""
    dialect.check_pnu(pnu)
    page = 0
    if dialect.pnu_bits == 12:
        number = pnu
    elif dialect.page_index:
        multiple, number = divmod(pnu, PAGE_SIZE)
        page = page_index(multiple)
    else:
        number = pnu
    pke = (ak << 12) | number
    other = page or high
    if layout is IndLayout.USS:
        return pke, (other << 8) | subindex
    return pke, (subindex << 8) | other


def decode_pke_ind(dialect: Dialect, layout: IndLayout, pke: int, ind: int) -> tuple[int, int, int]:
    """AK, PNU (page index applied) and subindex of a PKE and IND."""
    if layout is IndLayout.USS:
        subindex, other = ind & 0xFF, ind >> 8
    else:
        subindex, other = ind >> 8, ind & 0xFF
    ak = pke >> 12
    if dialect.pnu_bits == 12:
        return ak, pke & 0xFFF, subindex
    pnu = pke & _PNU_MASK_11
    if dialect.page_index:
        if pnu >= PAGE_SIZE:
            raise RemoteProtocolError(f"PNU field {pnu} beside a page index (1-1999 allowed)")
        pnu += PAGE_SIZE * page_multiple(other)
        if pnu > dialect.max_pnu:
            raise RemoteProtocolError(f"page index {other:#04x} makes PNU {pnu}, above 65535")
    return ak, pnu, subindex


# ----------------------------------------------------------------- encoding


def encode_request(
    req: PkwRequest, dialect: Dialect, layout: IndLayout, pkw_words: int | None
) -> bytes:
    """The PKW bytes of ``req`` for a block of ``pkw_words`` words (None = variable)."""
    high = 0
    if req.command is Command.TEXT and dialect.text_ind_high is not None:
        high = dialect.text_ind_high[1 if req.text else 0]
    pke, ind = encode_pke_ind(dialect, layout, req.ak, req.pnu, req.subindex, high)
    head = pke.to_bytes(2, "big") + ind.to_bytes(2, "big")
    if req.text:
        if pkw_words is not None:
            raise LocalProtocolError("a text write needs a variable-length PKW block")
        return head + req.text
    if pkw_words == 0:
        raise LocalProtocolError("this drive has no PKW channel (PKW length 0)")
    if pkw_words == 3:
        if req.width is Width.DWORD or req.value > 0xFFFF:
            raise LocalProtocolError("a double word does not fit a PKW block of 3 words")
        return head + req.value.to_bytes(2, "big")
    return head + req.value.to_bytes(4, "big")


# ------------------------------------------------------- follower's side


def decode_request(pkw: bytes, dialect: Dialect, layout: IndLayout) -> PkwRequest:
    """Decode a PKW *request* (what a follower receives); inverse of :func:`encode_request`.

    A word request carries its value in PWE low. A text request writes when
    the dialect marks text writes in IND (FC: 0x05) and the marker is there,
    or, in a dialect without markers, when PKW is not a 2- or 4-byte PWE.
    """
    if len(pkw) < 4:
        raise RemoteProtocolError(f"PKW part of {len(pkw)} bytes is too short")
    pke = (pkw[0] << 8) | pkw[1]
    ind = (pkw[2] << 8) | pkw[3]
    ak, pnu, subindex = decode_pke_ind(dialect, layout, pke, ind)
    try:
        command = dialect.command(ak)
    except LocalProtocolError:
        raise RemoteProtocolError(
            f"request identifier {ak} is not in the {dialect.name} table"
        ) from None
    rest = bytes(pkw[4:])
    if command is Command.TEXT and _is_text_write(dialect, layout, ind, rest):
        return PkwRequest(ak, command, pnu, subindex, 0, rest)
    value, low = _pwe(rest)
    if command not in DWORD_COMMANDS and command is not Command.READ_DESCRIPTION:
        value = low
    return PkwRequest(ak, command, pnu, subindex, value)


def _is_text_write(dialect: Dialect, layout: IndLayout, ind: int, rest: bytes) -> bool:
    if dialect.text_ind_high is not None:
        other = ind >> 8 if layout is IndLayout.USS else ind & 0xFF
        return other == dialect.text_ind_high[1] and bool(rest)
    return len(rest) not in (2, 4)


def response_id(dialect: Dialect, reply: Reply) -> int:
    """The response identifier a follower of ``dialect`` sends for ``reply``.

    An array reply falls back to the plain one where the dialect has no
    array identifier (FC answers array elements with AK 1 and 2).
    """
    fallback = {Reply.ARRAY_WORD: Reply.WORD, Reply.ARRAY_DWORD: Reply.DWORD}
    for wanted in (reply, fallback.get(reply)):
        for ak, (kind, _) in dialect.responses.items():
            if kind is wanted:
                return ak
    raise LocalProtocolError(f"the {dialect.name} dialect has no response for {reply.value}")


# ----------------------------------------------------------------- decoding


@dataclass(frozen=True, slots=True)
class PkwResponse:
    """Base of every decoded PKW response."""

    ak: int
    pnu: int
    subindex: int


@dataclass(frozen=True, slots=True)
class NoResponse(PkwResponse):
    """AK 0: the follower has nothing to say (yet)."""


@dataclass(frozen=True, slots=True)
class ValueResponse(PkwResponse):
    raw: int
    width: Width


@dataclass(frozen=True, slots=True)
class DescriptionResponse(PkwResponse):
    raw: int
    data: bytes


@dataclass(frozen=True, slots=True)
class ArrayCountResponse(PkwResponse):
    count: int


@dataclass(frozen=True, slots=True)
class Rejection(PkwResponse):
    """The drive refused: ``fault`` is PWE low (None for "no change rights"), ``text`` says why."""

    fault: int | None
    text: str
    short: str


@dataclass(frozen=True, slots=True)
class TextResponse(PkwResponse):
    text: bytes


@dataclass(frozen=True, slots=True)
class SpontaneousResponse(PkwResponse):
    raw: int


# The short text of a "no change rights" answer, which carries no fault number.
NO_CHANGE_RIGHTS = "no change rights"


def rejections(dialect: Dialect) -> list[tuple[int | None, str]]:
    """Every (fault, short) pair a :class:`Rejection` decoded in ``dialect`` can carry.

    The fault numbers of the dialect's table, and "no change rights" (no
    number) where the dialect has that answer. A number outside the table is
    kept with a made-up text (:meth:`Dialect.fault`) and is not listed.
    """
    known: list[tuple[int | None, str]] = [(f.number, f.short) for f in dialect.faults.values()]
    if any(reply is Reply.NO_RIGHTS for reply, _ in dialect.responses.values()):
        known.append((None, NO_CHANGE_RIGHTS))
    return known


def _pwe(data: bytes) -> tuple[int, int]:
    """(PWE as a double word, PWE low word); a 3-word block has only the low word."""
    if len(data) >= 4:
        value = int.from_bytes(data[:4], "big")
        return value, value & 0xFFFF
    if len(data) == 2:
        low = int.from_bytes(data, "big")
        return low, low
    raise RemoteProtocolError(f"PWE of {len(data)} bytes")


def decode_response(pkw: bytes, dialect: Dialect, layout: IndLayout) -> PkwResponse:
    """Decode a PKW response; the response identifier decides word or double word."""
    if len(pkw) < 4:
        raise RemoteProtocolError(f"PKW part of {len(pkw)} bytes is too short")
    pke = (pkw[0] << 8) | pkw[1]
    ind = (pkw[2] << 8) | pkw[3]
    ak, pnu, subindex = decode_pke_ind(dialect, layout, pke, ind)
    reply = dialect.reply(ak)
    rest = pkw[4:]
    if reply is None:
        raise RemoteProtocolError(f"response identifier {ak} is not in the {dialect.name} table")
    if reply is Reply.NONE:
        return NoResponse(ak, pnu, subindex)
    if reply is Reply.TEXT:
        return TextResponse(ak, pnu, subindex, bytes(rest))
    value, low = _pwe(rest)
    if reply in (Reply.WORD, Reply.ARRAY_WORD):
        return ValueResponse(ak, pnu, subindex, low, Width.WORD)
    if reply in (Reply.DWORD, Reply.ARRAY_DWORD):
        if len(rest) < 4:
            raise RemoteProtocolError("a double word answer in a PKW block of 3 words")
        return ValueResponse(ak, pnu, subindex, value, Width.DWORD)
    if reply is Reply.REJECTED:
        fault = dialect.fault(low)
        return Rejection(ak, pnu, subindex, low, fault.text, fault.short)
    if reply is Reply.NO_RIGHTS:
        text = dialect.response_text(ak)
        return Rejection(ak, pnu, subindex, None, text, NO_CHANGE_RIGHTS)
    if reply is Reply.DESCRIPTION:
        return DescriptionResponse(ak, pnu, subindex, value, bytes(rest))
    if reply is Reply.ARRAY_COUNT:
        return ArrayCountResponse(ak, pnu, subindex, low)
    return SpontaneousResponse(ak, pnu, subindex, value)


def encode_response(
    resp: PkwResponse, dialect: Dialect, layout: IndLayout, pkw_words: int | None
) -> bytes:
    """The PKW bytes of a response (what a follower sends; used by the simulator)."""
    high = 0
    if isinstance(resp, TextResponse) and dialect.text_ind_high is not None:
        high = dialect.text_ind_high[0]
    pke, ind = encode_pke_ind(dialect, layout, resp.ak, resp.pnu, resp.subindex, high)
    head = pke.to_bytes(2, "big") + ind.to_bytes(2, "big")
    if isinstance(resp, TextResponse):
        return head + resp.text
    if isinstance(resp, DescriptionResponse) and resp.data and pkw_words is None:
        return head + resp.data  # a text element (the name) in a variable block
    if isinstance(resp, ValueResponse | DescriptionResponse | SpontaneousResponse):
        value = resp.raw
    elif isinstance(resp, ArrayCountResponse):
        value = resp.count
    elif isinstance(resp, Rejection):
        value = resp.fault or 0
    else:
        value = 0
    if pkw_words == 3:
        if value > 0xFFFF:
            raise LocalProtocolError("a double word does not fit a PKW block of 3 words")
        return head + value.to_bytes(2, "big")
    return head + value.to_bytes(4, "big")


# ----------------------------------------------------------------- matching


def matches(req: PkwRequest, resp: PkwResponse, dialect: Dialect) -> bool:
    """Seed 003's rule: does ``resp`` answer ``req``?

    The identifier must be a positive or negative acknowledgement of the
    request's, PNU and subindex must be the request's, and a positive answer
    to a change must echo the value written. Anything else is "not yet".
    """
    if req.command is Command.NONE:
        return False
    if not dialect.accepts(req.ak, resp.ak):
        return False
    if resp.pnu != req.pnu or resp.subindex != req.subindex:
        return False
    if isinstance(resp, Rejection):
        return True
    if req.is_write and isinstance(resp, ValueResponse):
        written = req.value if resp.width is Width.DWORD else req.value & 0xFFFF
        return resp.raw == written and (resp.width is Width.DWORD or req.value <= 0xFFFF)
    return True
