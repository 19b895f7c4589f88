"""PKW requests: building them for a dialect, and their bytes both ways.

:func:`request` and its shorthands (:func:`read`, :func:`write`, ...) build a
:class:`PkwRequest` a dialect can say; :func:`encode_request` gives its bytes
and :func:`decode_request` is the follower's inverse (used by the simulator).

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for a request the
dialect or the PKW block cannot carry, and
:class:`~pkwbus.protocol.errors.RemoteProtocolError` for received request
bytes that do not decode.
"""

from __future__ import annotations

from dataclasses import dataclass

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import DWORD_COMMANDS, WRITE_COMMANDS, Command, Dialect, IndLayout
from pkwbus.protocol.pkw.fields import Store, Width, decode_pke_ind, decode_pwe, encode_pke_ind

__all__ = [
    "VARIABLE_READ_PWE",
    "PkwRequest",
    "decode_request",
    "encode_request",
    "none_request",
    "read",
    "read_description",
    "read_parameter",
    "read_text",
    "request",
    "write",
    "write_text",
]


# PWE of a variable-length request that carries no value (read, description, AK 0):
# one word, 0. The drive ignores PWE when a value is requested (MICROMASTER 420
# Reference Manual, 3.3.5), and one PWE word is the shortest block any task has.
VARIABLE_READ_PWE: bytes = b"\x00\x00"


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


# ----------------------------------------------------------------- encoding


def encode_request(
    req: PkwRequest, dialect: Dialect, layout: IndLayout, pkw_words: int | None
) -> bytes:
    """The PKW bytes of ``req`` for a block of ``pkw_words`` words (None = variable).

    Fixed 4 words: a word right-justified in PWE2, PWE1 = 0; fixed 3: the word
    in PWE. Variable (USS PKW length 127): only what the task needs, a word
    in PWE1, a double word in PWE1 (high) and PWE2 (low), a text as long as
    it is, and a request without a value :data:`VARIABLE_READ_PWE` (USS
    specification, part C, 4.1.2; SIMOVERT MASTERDRIVES Compendium Motion
    Control, 8.1, PKW area variable: "PWE1 contains the value. There is no
    PWE2"; SINAMICS S110 Function Manual, 9.5: "the master will only send
    the number of words necessary for the task").
    """
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
    if pkw_words is None:
        return head + _variable_pwe(req)
    if pkw_words == 3:
        if req.width is Width.DWORD or req.value > 0xFFFF:
            raise LocalProtocolError("a double word does not fit a PKW block of 3 words")
        return head + req.value.to_bytes(2, "big")
    return head + req.value.to_bytes(4, "big")


def _variable_pwe(req: PkwRequest) -> bytes:
    """PWE of a variable-length request: as many words as the task's value needs."""
    if req.command in DWORD_COMMANDS:
        return req.value.to_bytes(4, "big")
    if req.command in WRITE_COMMANDS:
        return req.value.to_bytes(2, "big")
    return VARIABLE_READ_PWE


# ------------------------------------------------------- follower's side


def decode_request(
    pkw: bytes, dialect: Dialect, layout: IndLayout, pkw_words: int | None = 4
) -> PkwRequest:
    """Decode a PKW *request* (what a follower receives); inverse of :func:`encode_request`.

    A word request carries its value where the follower's PKW length puts it:
    PWE2 (the low word) with 4 fixed words, PWE1 (the first PWE word) with a
    variable length (USS specification, part C, 4.1.2), the one PWE word with
    3. A text request writes when the dialect marks text writes in IND (FC:
    0x05) and the marker is there, or, in a dialect without markers, when PKW
    is not a 2- or 4-byte PWE.
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
    if not rest and pkw_words is None and command not in WRITE_COMMANDS:
        return PkwRequest(ak, command, pnu, subindex, 0)  # variable: no PWE needed
    value, low = decode_pwe(rest)
    if command not in DWORD_COMMANDS and command is not Command.READ_DESCRIPTION:
        value = value >> 16 if pkw_words is None and len(rest) >= 4 else low
    return PkwRequest(ak, command, pnu, subindex, value)


def _is_text_write(dialect: Dialect, layout: IndLayout, ind: int, rest: bytes) -> bool:
    if dialect.text_ind_high is not None:
        other = ind >> 8 if layout is IndLayout.USS else ind & 0xFF
        return other == dialect.text_ind_high[1] and bool(rest)
    return len(rest) not in (2, 4)
