"""PKW responses: decoding, encoding (the follower's side) and matching to a request.

:func:`decode_response` turns a PKW block into one of the :class:`PkwResponse`
kinds, the response identifier deciding word or double word;
:func:`matches` applies the rule of the SINAMICS G120 CU240B-2/CU240E-2
Operating Instructions, section 6.3: the response identifier fits, PNU and IND
are the request's, and a change is echoed in PWE.

Raises :class:`~pkwbus.protocol.errors.RemoteProtocolError` for response
bytes that do not decode, and :class:`~pkwbus.protocol.errors.LocalProtocolError`
for a response the dialect or the PKW block cannot carry.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Command, Dialect, IndLayout, Reply
from pkwbus.protocol.pkw.fields import Width, decode_pke_ind, decode_pwe, encode_pke_ind
from pkwbus.protocol.pkw.requests import PkwRequest
from pkwbus.protocol.values.types import ValueType

__all__ = [
    "NO_CHANGE_RIGHTS",
    "ArrayCountResponse",
    "ChangeDone",
    "DescriptionResponse",
    "NoResponse",
    "PkwResponse",
    "Rejection",
    "SpontaneousResponse",
    "TextResponse",
    "ValueResponse",
    "Verdict",
    "decode_response",
    "encode_response",
    "judge",
    "matches",
    "rejections",
    "response_id",
]


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
    """A value: ``raw`` as an unsigned number of ``width``. ``vtype``: the type the answer
    itself names (a PROFIdrive parameter response's format); None for a PKW answer, which
    tells only the width."""

    raw: int
    width: Width
    vtype: ValueType | None = None


@dataclass(frozen=True, slots=True)
class ChangeDone(PkwResponse):
    """A change carried out, its value not echoed: a PROFIdrive parameter response to a
    change request carries none (SINAMICS G120X operating instructions, table 6-16)."""


@dataclass(frozen=True, slots=True)
class DescriptionResponse(PkwResponse):
    """A description element: ``raw`` as a number, ``data`` the PWE bytes as sent.

    ``width``: a numeric element's size, which a variable-length PKW block
    shows (one PWE word or two); a text element (the name) is ``data``.
    """

    raw: int
    data: bytes
    width: Width = Width.DWORD


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
    value, low = decode_pwe(rest)
    if reply in _WORD_REPLIES:
        return ValueResponse(ak, pnu, subindex, low, Width.WORD)
    if reply in _DWORD_REPLIES:
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
        width = Width.WORD if len(rest) == 2 else Width.DWORD
        return DescriptionResponse(ak, pnu, subindex, value, bytes(rest), width)
    if reply is Reply.ARRAY_COUNT:
        return ArrayCountResponse(ak, pnu, subindex, low)
    return SpontaneousResponse(ak, pnu, subindex, value)


_WORD_REPLIES = (Reply.WORD, Reply.ARRAY_WORD)
_DWORD_REPLIES = (Reply.DWORD, Reply.ARRAY_DWORD)


def encode_response(
    resp: PkwResponse, dialect: Dialect, layout: IndLayout, pkw_words: int | None
) -> bytes:
    """The PKW bytes of a response (what a follower sends; used by the simulator).

    With a variable PKW length (None) the block is as long as the answer
    needs: a word value, a fault number or a count in PWE1, a double word in
    PWE1 and PWE2, a text as long as it is, AK 0 as PKE and IND alone (USS
    specification, part C, 4.1.2).
    """
    high = 0
    if isinstance(resp, TextResponse) and dialect.text_ind_high is not None:
        high = dialect.text_ind_high[0]
    pke, ind = encode_pke_ind(dialect, layout, resp.ak, resp.pnu, resp.subindex, high)
    head = pke.to_bytes(2, "big") + ind.to_bytes(2, "big")
    if isinstance(resp, TextResponse):
        return head + resp.text
    if isinstance(resp, DescriptionResponse) and resp.data and pkw_words is None:
        return head + resp.data  # a text element (the name) in a variable block
    width = Width.WORD
    if isinstance(resp, ValueResponse | DescriptionResponse):
        value, width = resp.raw, resp.width
    elif isinstance(resp, SpontaneousResponse):
        value, width = resp.raw, Width.DWORD
    elif isinstance(resp, ArrayCountResponse):
        value = resp.count
    elif isinstance(resp, Rejection):
        value = resp.fault or 0
    else:
        if pkw_words is None:
            return head  # AK 0: nothing to carry
        value = 0
    if pkw_words == 3 or (pkw_words is None and width is Width.WORD):
        if value > 0xFFFF:
            raise LocalProtocolError("a double word does not fit a PKW block of 3 words")
        return head + value.to_bytes(2, "big")
    return head + value.to_bytes(4, "big")


# ----------------------------------------------------------------- matching


def matches(req: PkwRequest, resp: PkwResponse, dialect: Dialect) -> bool:
    """Does ``resp`` answer ``req`` (SINAMICS G120 Operating Instructions, section 6.3)?

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


class Verdict(enum.Enum):
    """What an answer is to a request: its answer, not yet, or a change the drive
    acknowledged with another value than the one sent."""

    ANSWER = "answer"
    NOT_YET = "not yet"
    MISMATCH = "mismatch"


def judge(req: PkwRequest, resp: PkwResponse, dialect: Dialect) -> Verdict:
    """:func:`matches`, and a positive answer to a change with another value: the drive
    took something other than what was sent, and a repeat would write it again."""
    if matches(req, resp, dialect):
        return Verdict.ANSWER
    if (
        req.is_write
        and isinstance(resp, ValueResponse)
        and dialect.accepts(req.ak, resp.ak)
        and (resp.pnu, resp.subindex) == (req.pnu, req.subindex)
    ):
        return Verdict.MISMATCH
    return Verdict.NOT_YET
