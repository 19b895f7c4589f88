"""A simulated drive's PROFIdrive fault buffer, of a given shape and P948 type, answered
through the PKW channel (a DP slave's PPO words) and data record 47: P944, P947 to P950
and P952, ahead of the drive's own parameters of those numbers.

Laid out as the profile words it: P950[0] fault situations of P950[1] messages,
situation s's message m at subindex s x P950[1] + m (Siemens PROFIdrive application
example PDRV V4.2); a fault enters the active situation [0] at its next free message, in
the sequence the faults come; an acknowledgement moves the situations down by one, the
oldest dropped ([0] active, [1] the latest acknowledged: VACON 100 Installation Manual,
p. 27; ABB RETA-02 User's Manual, pp. 100-102). P944 counts every change, from 0xFFFF
on to 1 (PDRV); P952 counts the faults entered (ABB RPBA-01: "Number of faults
occurred"). An empty place reads 0. The simulator's choices, where the documents say
nothing: a fault beyond a situation's last message overwrites that message (as the
SINAMICS buffer does: S200 Operating Instructions, appendix A.3); an acknowledgement
with none active changes nothing; P949 is an Integer32 (as SINAMICS r0949); P952 cannot
be written here.

P948 in the type :class:`BufferKind` names, which its description's identifier (element
1) says: Unsigned16 (6) "seconds since the last fault occurred" (ABB RPBA-01, p. 103),
here the seconds the drive was powered since (stopping at 65,535); Unsigned32 (7)
seconds, here of its runtime at the fault (r2114's base); TimeDifference with date (53:
ms, days) or without (54: ms), here its runtime at the fault. Six bytes do not fit the
PKW channel's PWE (two words): a TimeDifference with date is refused there, with the
fault the drive answers for a value too wide for its channel.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw import PkwRequest, PkwResponse, Width
from pkwbus.protocol.pkw.dialects import Command, Dialect, Reply
from pkwbus.protocol.profidrive.parameters import (
    Attribute,
    Format,
    ParameterAddress,
    ParameterError,
    Values,
)
from pkwbus.sim.drives.logs import DAY_MS
from pkwbus.sim.drives.params import ARRAY_COMMANDS, FaultNumbers

__all__ = ["PNUS", "TIME_TYPES", "BufferKind", "ProfidriveFaultBuffer"]

PNUS: Final = frozenset({944, 947, 948, 949, 950, 952})
# P948's data type -> its format in data record 47.
TIME_TYPES: Final = {
    6: Format.U16,
    7: Format.U32,
    53: Format.TIME_DIFFERENCE_WITH_DATE,
    54: Format.TIME_DIFFERENCE_WITHOUT_DATE,
}
_WIDE = frozenset({Format.TIME_DIFFERENCE_WITH_DATE})  # more than PWE's two words
_ARRAY, _READ_ONLY = 1 << 14, 1 << 9  # identifier bits (Danfoss MG.33.C4.02, section 5)
_INVALID_SUBINDEX, _NO_DESCRIPTION = 0x03, 0x09  # PROFIdrive error numbers
_TOP_U16 = 0xFFFF


@dataclass(frozen=True, slots=True)
class BufferKind:
    """The buffer's shape (P950) and P948's data type (a key of :data:`TIME_TYPES`)."""

    situations: int = 8
    messages: int = 1
    time_type: int = 6

    def __post_init__(self) -> None:
        if self.time_type not in TIME_TYPES:
            raise ValueError(f"P948 of data type {self.time_type}: the simulator has 6, 7, 53, 54")
        if not 1 <= self.situations * self.messages <= 256:
            raise ValueError(f"a buffer of {self.situations} x {self.messages}: 1 to 256 places")


@dataclass(frozen=True, slots=True)
class _Message:
    number: int
    value: int
    runtime_ms: int  # the drive's runtime at the fault (r2114's base)
    powered_ms: int  # the time it had been powered, over all power-ups


class ProfidriveFaultBuffer:
    """The buffer: ``held[0]`` the active situation, ``held[k]`` the k-th acknowledged."""

    def __init__(self, kind: BufferKind) -> None:
        self.kind = kind
        self.held: list[list[_Message]] = [[] for _ in range(kind.situations)]
        self.counter = 0  # P944
        self.entered = 0  # P952

    def enter(self, number: int, value: int, runtime_ms: int, powered_ms: int) -> None:
        """A fault comes: into the active situation's next free message, or over its last."""
        active = self.held[0]
        message = _Message(number, value, runtime_ms, powered_ms)
        if len(active) < self.kind.messages:
            active.append(message)
        else:
            active[-1] = message
        self.entered = (self.entered + 1) & 0xFFFF
        self._changed()

    def acknowledge(self) -> None:
        """The situations move down by one, the oldest dropped; none active: no change."""
        if self.held[0]:
            self.held = [[], *self.held[:-1]]
            self._changed()

    def _changed(self) -> None:
        self.counter = self.counter % 0xFFFF + 1  # from 0xFFFF on to 1

    # ------------------------------------------------------------ values

    @property
    def places(self) -> int:
        return self.kind.situations * self.kind.messages

    def size(self, pnu: int) -> int:
        """Elements of ``pnu`` (0: not an array)."""
        return {947: self.places, 948: self.places, 949: self.places, 950: 2}.get(pnu, 0)

    def format(self, pnu: int) -> Format:
        if pnu == 948:
            return TIME_TYPES[self.kind.time_type]
        return Format.I32 if pnu == 949 else Format.U16

    def identifier(self, pnu: int) -> int:
        """Description element 1: the data type, array and read-only bits."""
        kind = self.kind.time_type if pnu == 948 else int(self.format(pnu))
        return kind | (_ARRAY if self.size(pnu) else 0) | _READ_ONLY

    def value(self, pnu: int, index: int, powered_ms: int) -> int:
        """``pnu``[``index``] now (the drive powered ``powered_ms`` over all power-ups)."""
        if pnu == 944:
            return self.counter
        if pnu == 952:
            return self.entered
        if pnu == 950:
            return (self.kind.situations, self.kind.messages)[index]
        situation, place = divmod(index, self.kind.messages)
        there = self.held[situation]
        if place >= len(there):
            return 0
        m = there[place]
        if pnu == 947:
            return m.number
        if pnu == 949:
            return m.value
        return self._time(m, powered_ms)

    def _time(self, m: _Message, powered_ms: int) -> int:
        kind = self.kind.time_type
        if kind == 6:
            return min((powered_ms - m.powered_ms) // 1000, _TOP_U16)
        if kind == 7:
            return m.runtime_ms // 1000 & 0xFFFFFFFF
        if kind == 53:
            days, within = divmod(m.runtime_ms, DAY_MS)
            return within << 16 | days & 0xFFFF
        return m.runtime_ms & 0xFFFFFFFF

    def _index_fault(self, pnu: int, index: int, faults: FaultNumbers) -> int | None:
        """The fault number for ``index`` of ``pnu`` (None: the drive has it)."""
        size = self.size(pnu)
        if not size and index:
            return faults.not_array
        return faults.subindex if size and index >= size else None

    # ----------------------------------------------------------- answers

    def answer_pkw(
        self, req: PkwRequest, dialect: Dialect, faults: FaultNumbers, powered_ms: int
    ) -> PkwResponse | None:
        """The PKW answer to ``req`` (None: not one of the buffer's parameters)."""
        if req.pnu not in PNUS or req.command is Command.NONE:
            return None
        command, pnu, index = req.command, req.pnu, req.subindex
        if command is Command.READ_DESCRIPTION:
            element = self._element(pnu, index)
            if element is None:
                return _refused(req, dialect, faults.no_description)
            ak = pkw.response_id(dialect, Reply.DESCRIPTION)
            return pkw.DescriptionResponse(ak, pnu, index, element, b"", Width.WORD)
        if command is Command.READ_ARRAY_COUNT:
            if not self.size(pnu):
                return _refused(req, dialect, faults.not_array)
            count = pkw.response_id(dialect, Reply.ARRAY_COUNT)
            return pkw.ArrayCountResponse(count, pnu, index, self.size(pnu))
        if command is Command.TEXT:
            return _refused(req, dialect, faults.no_text)
        if req.is_write:
            return _refused(req, dialect, faults.read_only)
        wrong = self._index_fault(pnu, index, faults)
        if wrong is not None:
            return _refused(req, dialect, wrong)
        fmt = self.format(pnu)
        if fmt in _WIDE:
            return _refused(req, dialect, faults.channel)  # six bytes do not fit PWE
        width = Width.WORD if fmt.size <= 2 else Width.DWORD
        raw = self.value(pnu, index, powered_ms) & ((1 << width.value) - 1)
        array = command in ARRAY_COMMANDS
        if width is Width.WORD:
            reply = Reply.ARRAY_WORD if array else Reply.WORD
        else:
            reply = Reply.ARRAY_DWORD if array else Reply.DWORD
        return pkw.ValueResponse(pkw.response_id(dialect, reply), pnu, index, raw, width)

    def answer_record(
        self, address: ParameterAddress, faults: FaultNumbers, powered_ms: int
    ) -> Values | ParameterError | None:
        """One parameter of a data record 47 read (None: not one of the buffer's)."""
        pnu, first = address.pnu, address.subindex
        if pnu not in PNUS:
            return None
        if address.attribute is Attribute.TEXT:
            return ParameterError(faults.no_text)
        if address.attribute is Attribute.DESCRIPTION:
            element = self._element(pnu, first)
            if element is None:
                return ParameterError(_NO_DESCRIPTION)
            return Values(Format.U16, (element,))
        indexes = range(first, first + max(address.elements, 1))
        size = self.size(pnu)
        if (not size and (first or address.elements > 1)) or (size and indexes[-1] >= size):
            return ParameterError(_INVALID_SUBINDEX, first)
        return Values(self.format(pnu), tuple(self.value(pnu, i, powered_ms) for i in indexes))

    def _element(self, pnu: int, element: int) -> int | None:
        if element == 1:
            return self.identifier(pnu)
        if element == 2:
            return self.size(pnu)
        return None


def _refused(req: PkwRequest, dialect: Dialect, fault: int) -> PkwResponse:
    text = dialect.fault(fault)
    ak = pkw.response_id(dialect, Reply.REJECTED)
    return pkw.Rejection(ak, req.pnu, req.subindex, fault, text.text, text.short)
