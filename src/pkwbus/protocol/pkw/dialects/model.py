"""What a PKW request asks and a response carries, and the type of one dialect's tables.

:class:`Command` and :class:`Reply` name requests and responses independently
of any dialect's numbering; :class:`Dialect` holds one dialect's numbering,
fault texts and IND/PNU layout (the tables themselves are in
:mod:`pkwbus.protocol.pkw.dialects.tables`, the dialects in
:mod:`pkwbus.protocol.pkw.dialects`).

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` from
:meth:`Dialect.check_pnu`, :meth:`Dialect.request_id` and :meth:`Dialect.command`
when the dialect cannot encode the parameter number or has no such request.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from pkwbus.protocol.errors import LocalProtocolError

__all__ = [
    "DWORD_COMMANDS",
    "NEGATIVE_REPLIES",
    "VALUE_REPLIES",
    "WRITE_COMMANDS",
    "Command",
    "Dialect",
    "Fault",
    "IndLayout",
    "Reply",
]


class Command(enum.Enum):
    """What a PKW request asks for, independent of the dialect's numbering."""

    NONE = "none"
    READ = "read"
    READ_ARRAY = "read array element"
    WRITE_WORD = "write word"
    WRITE_DWORD = "write double word"
    WRITE_ARRAY_WORD = "write array word"
    WRITE_ARRAY_DWORD = "write array double word"
    WRITE_WORD_EEPROM = "write word to RAM and EEPROM"
    WRITE_DWORD_EEPROM = "write double word to RAM and EEPROM"
    WRITE_ARRAY_WORD_EEPROM = "write array word to RAM and EEPROM"
    WRITE_ARRAY_DWORD_EEPROM = "write array double word to RAM and EEPROM"
    READ_DESCRIPTION = "read description element"
    WRITE_DESCRIPTION = "write description element"
    READ_ARRAY_COUNT = "read number of array elements"
    TEXT = "read/write text"


class Reply(enum.Enum):
    """What a PKW response carries."""

    NONE = "none"
    WORD = "word value"
    DWORD = "double word value"
    ARRAY_WORD = "array word value"
    ARRAY_DWORD = "array double word value"
    DESCRIPTION = "description element"
    ARRAY_COUNT = "number of array elements"
    REJECTED = "rejected"
    NO_RIGHTS = "no change rights"
    TEXT = "text"
    SPONTANEOUS = "spontaneous message"


VALUE_REPLIES = frozenset({Reply.WORD, Reply.DWORD, Reply.ARRAY_WORD, Reply.ARRAY_DWORD})
NEGATIVE_REPLIES = frozenset({Reply.REJECTED, Reply.NO_RIGHTS})

WRITE_COMMANDS = frozenset(
    {
        Command.WRITE_WORD,
        Command.WRITE_DWORD,
        Command.WRITE_ARRAY_WORD,
        Command.WRITE_ARRAY_DWORD,
        Command.WRITE_WORD_EEPROM,
        Command.WRITE_DWORD_EEPROM,
        Command.WRITE_ARRAY_WORD_EEPROM,
        Command.WRITE_ARRAY_DWORD_EEPROM,
    }
)
DWORD_COMMANDS = frozenset(
    {
        Command.WRITE_DWORD,
        Command.WRITE_ARRAY_DWORD,
        Command.WRITE_DWORD_EEPROM,
        Command.WRITE_ARRAY_DWORD_EEPROM,
    }
)


class IndLayout(enum.StrEnum):
    """Where the subindex sits in IND.

    ``uss``: subindex in the low byte, page index (or 0) in the high byte
    (USS specification, Danfoss FC). ``profidrive``: subindex in the high
    byte, page index (or 0) in the low byte (PROFIBUS PPO, Danfoss PCV,
    Hitachi SJ-PB).
    """

    USS = "uss"
    PROFIDRIVE = "profidrive"


@dataclass(frozen=True, slots=True)
class Fault:
    number: int
    text: str
    short: str


@dataclass(frozen=True)
class Dialect:
    """One dialect's tables, looked up with :func:`pkwbus.protocol.pkw.dialects.dialect`."""

    name: str
    title: str
    pnu_bits: int
    page_index: bool
    default_ind_layout: IndLayout
    requests: Mapping[int, tuple[Command, str]]
    responses: Mapping[int, tuple[Reply, str]]
    faults: Mapping[int, Fault]
    text_ind_high: tuple[int, int] | None = None  # (read, write) IND high byte for text
    # Danfoss drives number parameters in groups: PNU 341 is 3-41, never r/p0341.
    danfoss_numbers: bool = False
    _ak_of: Mapping[Command, int] = field(init=False, repr=False)
    _reply_of: Mapping[int, Reply] = field(init=False, repr=False)
    # Per request identifier, the response identifiers that acknowledge it (accepts()).
    _acks: Mapping[int, frozenset[int]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        ak_of: dict[Command, int] = {}
        for ak, (command, _) in self.requests.items():
            ak_of.setdefault(command, ak)
        object.__setattr__(self, "_ak_of", MappingProxyType(ak_of))
        reply_of = {ak: reply for ak, (reply, _) in self.responses.items()}
        object.__setattr__(self, "_reply_of", MappingProxyType(reply_of))
        acks = {
            ak: frozenset(r for r, reply in reply_of.items() if _acknowledges(command, reply))
            for ak, (command, _) in self.requests.items()
        }
        object.__setattr__(self, "_acks", MappingProxyType(acks))

    @property
    def max_pnu(self) -> int:
        if self.page_index:
            return 0xFFFF
        return (1 << self.pnu_bits) - 1

    def check_pnu(self, pnu: int) -> None:
        if not 0 <= pnu <= self.max_pnu:
            raise LocalProtocolError(
                f"parameter number {pnu} cannot be encoded in the {self.name} dialect "
                f"(0-{self.max_pnu})"
            )

    def has(self, command: Command) -> bool:
        return command in self._ak_of

    def request_id(self, command: Command) -> int:
        """The AK this dialect uses for ``command``; a clear error when it has none."""
        try:
            return self._ak_of[command]
        except KeyError:
            raise LocalProtocolError(
                f"the {self.name} dialect has no request to {command.value}"
            ) from None

    def command(self, ak: int) -> Command:
        try:
            return self.requests[ak][0]
        except KeyError:
            raise LocalProtocolError(
                f"the {self.name} dialect has no request identifier {ak}"
            ) from None

    def reply(self, ak: int) -> Reply | None:
        """What response identifier ``ak`` carries, None when the table has no such identifier."""
        return self._reply_of.get(ak)

    def response_text(self, ak: int) -> str:
        entry = self.responses.get(ak)
        return entry[1] if entry else f"response identifier {ak}"

    def fault(self, number: int) -> Fault:
        """The fault of that number; the number is kept when the table has no text for it."""
        known = self.faults.get(number)
        if known is not None:
            return known
        return Fault(number, f"fault {number} (not in the {self.name} table)", f"fault {number}")

    def accepts(self, request_ak: int, response_ak: int) -> bool:
        """Whether ``response_ak`` is a positive or negative acknowledgement of ``request_ak``
        (LocalProtocolError: the dialect has no such request identifier)."""
        acks = self._acks.get(request_ak)
        if acks is None:
            raise LocalProtocolError(
                f"the {self.name} dialect has no request identifier {request_ak}"
            )
        return response_ak in acks


def _acknowledges(command: Command, reply: Reply) -> bool:
    """Whether a response carrying ``reply`` acknowledges a request for ``command``."""
    if command is Command.NONE:
        return reply is Reply.NONE
    return reply in NEGATIVE_REPLIES or reply in _POSITIVE[command]


# Positive acknowledgements per request (Hitachi SJ-PB(T) User Manual, chapter 5, widened where the
# manuals say drives answer otherwise: a read of a 32-bit parameter may come
# back as a word, SINAMICS treats 1=6, 2=7, 3=8).
_WORD_ACK = frozenset({Reply.WORD, Reply.ARRAY_WORD})
_DWORD_ACK = frozenset({Reply.DWORD, Reply.ARRAY_DWORD})
_POSITIVE: Mapping[Command, frozenset[Reply]] = {
    Command.READ: VALUE_REPLIES,
    Command.READ_ARRAY: VALUE_REPLIES,
    Command.WRITE_WORD: _WORD_ACK,
    Command.WRITE_ARRAY_WORD: _WORD_ACK,
    Command.WRITE_WORD_EEPROM: _WORD_ACK,
    Command.WRITE_ARRAY_WORD_EEPROM: _WORD_ACK,
    Command.WRITE_DWORD: _DWORD_ACK,
    Command.WRITE_ARRAY_DWORD: _DWORD_ACK,
    Command.WRITE_DWORD_EEPROM: _DWORD_ACK,
    Command.WRITE_ARRAY_DWORD_EEPROM: _DWORD_ACK,
    Command.READ_DESCRIPTION: frozenset({Reply.DESCRIPTION}),
    Command.WRITE_DESCRIPTION: frozenset({Reply.DESCRIPTION}),
    Command.READ_ARRAY_COUNT: frozenset({Reply.ARRAY_COUNT}),
    Command.TEXT: frozenset({Reply.TEXT}),
}
