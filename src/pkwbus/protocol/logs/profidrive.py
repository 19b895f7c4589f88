"""The PROFIdrive fault buffer of a drive of any make, read over PROFIBUS (the PPO's PKW
words or data record 47): P944 and P947 to P950.

The buffer holds fault situations of fault messages, one message a subindex: P950[0]
is the number of fault situations, P950[1] the messages per situation (Siemens
PROFIdrive application example PDRV V4.2, P950), so situation s's message m is at
subindex s x P950[1] + m. "Fault messages are entered into the buffer in the sequence
they are detected"; a fault situation "lasts from a detection of a fault to its
acknowledgement", and faults detected meanwhile belong to it (ABB RETA-02 User's Manual,
"Fault buffer mechanism", pp. 100-102). The newest situation is the first: [0] the
active fault, [1] the latest acknowledged, [7] the oldest (VACON 100 Installation
Manual, p. 27; Control Techniques SI-PROFIBUS User Guide: [0] active, [1] latest
acknowledged). The shape differs between makes: 8 x 8 (the PDRV example; LS S100), 8 x 1
(VACON 100, Control Techniques), 40 places (VACON OPTE9), 64 (ABB RETA-02 and RPBA-01,
"Array[64]"); so it is read from the drive at every sweep, and a drive that refuses P950
keeps no such buffer (:class:`~pkwbus.protocol.logs.model.NoSuchLog`).

P947 fault number; P949 fault value, read with a sign as the SINAMICS r0949 ("as
integer number"; ABB RPBA-01 lists no P949: a value the drive refuses is left out);
P944 the fault message counter, which changes with every change of the buffer and is
read before and after a sweep (VACON 100 reads the buffer consistently so; it wraps from
0xFFFF to 1: the PDRV example): a change meanwhile means the sweep is read again. What an
empty place reads is not stated; a fault number of 0 is taken as none, as for SINAMICS.

P948 fault time: its format differs between makes, so its data type is read from the
drive's own description of P948 (element 1, the identifier, bits 0-7), in the sweep's
first round:

- Unsigned16 (6): "Seconds since the last fault occurred" (ABB RPBA-01 User's Manual,
  "PROFIdrive parameters", p. 103): the entry's age, an
  :class:`~pkwbus.protocol.logs.model.Age` from when the drive answered that read; the
  reader places the entry on its own clock and knows it again by where.
- TimeDifference with date (53: ms and days) and without (54: ms) (PDRV example, data
  types): a duration, kept as the entry's drive time (a Runtime, read as days and ms),
  part of what tells it apart. No document read says from when it counts (ABB RETA-02,
  p. 95, names the type only), so there is no time now to place it by: ``seen``.
- Unsigned32 (7: seconds in the PDRV example, from when not said), TimeOfDay with date
  (12: ms and days since 1984-01-01, the drive's clock, whose setting is not known: kept
  as ms since then) and any other type: an opaque number, ``seen``.
- A drive that refuses the description: P948 is not read and its entries have no time
  (``seen``): a type not known may be an age, which would tell an entry apart from
  itself at every sweep.

A sweep, in rounds: P944, P950[0], P950[1] and P948's identifier; P947 of every place of
the shape; P949 and P948 of each fault there; P944 again. Entries newest first: the
situations in their order, in a situation the latest message first.
"""

from __future__ import annotations

from dataclasses import dataclass

from pkwbus.protocol.logs.model import (
    MS_PER_DAY,
    Age,
    Kind,
    LogEntry,
    NoSuchLog,
    Opaque,
    Read,
    Runtime,
    SweepResult,
    TimeBase,
    Values,
)
from pkwbus.protocol.pkw.descriptions import DATA_TYPE
from pkwbus.protocol.profidrive.parameters import Format

__all__ = [
    "COUNTER",
    "MAX_PLACES",
    "MESSAGES",
    "PROFIDRIVE_FAULT_BUFFER",
    "SITUATIONS",
    "TIME_TYPE",
    "ProfidriveFaultBuffer",
    "fault_time",
]

COUNTER = Read(944)  # P944 fault message counter
SITUATIONS = Read(950, 0)  # P950[0] number of fault situations
MESSAGES = Read(950, 1)  # P950[1] fault messages per situation
TIME_TYPE = Read(948, element=DATA_TYPE)  # P948's identifier: its data type in bits 0-7
MAX_PLACES = 256  # a PKW index is a byte (IND's low byte): the places pkwbus can address
_TOP_U16 = 0xFFFF


def _number(i: int) -> Read:
    return Read(947, i)  # P947 fault number


def _value(i: int) -> Read:
    return Read(949, i, signed=True)  # P949 fault value


def _time(i: int) -> Read:
    return Read(948, i)  # P948 fault time


def fault_time(kind: int | None, read: Read, raw: int | None) -> Runtime | Opaque | Age | None:
    """What P948's ``raw`` value (read by ``read``) says, by its data type ``kind`` (None:
    not known, or refused: no time)."""
    if kind is None or raw is None:
        return None
    if kind == Format.U16:
        return Age(raw & _TOP_U16, read, _TOP_U16)
    if kind == Format.TIME_DIFFERENCE_WITH_DATE:
        return Runtime.of(raw & 0xFFFF, raw >> 16 & 0xFFFFFFFF)
    if kind == Format.TIME_DIFFERENCE_WITHOUT_DATE:
        return Runtime(raw & 0xFFFFFFFF)
    if kind == Format.TIME_OF_DAY_WITH_DATE:
        return Opaque((raw & 0xFFFF) * MS_PER_DAY + (raw >> 16 & 0xFFFFFFFF))
    return Opaque(raw)


class _Sweep:
    """P944, the shape and P948's type; every fault number; the value and time of each
    fault there; P944 again."""

    def __init__(self) -> None:
        self.known: dict[Read, int | None] = {}
        self.counter_after: int | None = None
        self.places = 0
        self.messages = 1
        self.kind: int | None = None  # P948's data type (None: not described)
        self._round = 0

    def next(self) -> tuple[Read, ...]:
        if self._round == 0:
            return (COUNTER, SITUATIONS, MESSAGES, TIME_TYPE)
        if self._round == 1:
            return tuple(_number(i) for i in range(self.places))
        if self._round == 2:
            timed = self.kind is not None
            return tuple(
                r for i in self._present() for r in (_value(i), *((_time(i),) if timed else ()))
            )
        if self._round == 3:
            return (COUNTER,)
        return ()

    def feed(self, values: Values) -> None:
        if self._round == 0:
            self._shape(values)
        if self._round == 3:
            self.counter_after = values.get(COUNTER)
        else:
            self.known.update(values)
        self._round += 1
        if self._round == 2 and not self._present():
            self._round = 3  # an empty buffer: no details to read

    def _shape(self, values: Values) -> None:
        situations, messages = values.get(SITUATIONS), values.get(MESSAGES)
        if situations is None or messages is None:
            raise NoSuchLog("the drive refuses P950, the buffer's fault situations and messages")
        if not situations or not messages or situations * messages > MAX_PLACES:
            raise NoSuchLog(
                f"P950 gives {situations} fault situations of {messages} messages: pkwbus"
                f" reads a buffer of 1 to {MAX_PLACES} places"
            )
        self.places, self.messages = situations * messages, messages
        identifier = values.get(TIME_TYPE)
        self.kind = None if identifier is None else identifier & 0xFF

    def _present(self) -> list[int]:
        return [i for i in range(self.places) if self.known.get(_number(i))]

    def result(self) -> SweepResult | None:
        known = self.known
        if self._round < 4 or any(known.get(_number(i)) is None for i in range(self.places)):
            return None  # not over, or its fault numbers refused
        before = known.get(COUNTER)
        if before is None or before != self.counter_after:
            return None  # the buffer changed while it was read
        entries = []
        for first in range(0, self.places, self.messages):  # the newest situation first
            for i in reversed(range(first, first + self.messages)):  # its latest message first
                code = known[_number(i)]
                if not code:
                    continue
                when = fault_time(self.kind, _time(i), known.get(_time(i)))
                entries.append(LogEntry(Kind.FAULT, code, known.get(_value(i)), when))
        return SweepResult(tuple(entries), None)


@dataclass(frozen=True, slots=True)
class ProfidriveFaultBuffer:
    """The PROFIdrive fault buffer as a :class:`~pkwbus.protocol.logs.model.DriveLog`."""

    name: str = "PROFIdrive fault buffer"
    time_base: TimeBase = TimeBase.DESCRIBED
    runtime: tuple[Read, ...] = ()
    kinds: tuple[Kind, ...] = (Kind.FAULT,)

    def watch(self) -> tuple[Read, ...]:
        return (COUNTER,)

    def sweep(self, previous: SweepResult | None = None) -> _Sweep:
        return _Sweep()  # read whole each time: faults are rare, a change costs one sweep


PROFIDRIVE_FAULT_BUFFER = ProfidriveFaultBuffer()
