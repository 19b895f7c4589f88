"""A simulated drive's parameters: the store, live readings, and PKW requests executed on them.

A request the drive refuses raises :class:`Refused` (its fault number), answered as a
PKW fault. A value set at the drive's keypad (:meth:`ParameterStore.keypad`) is checked
as a bus write is, but refused with a ValueError.

Each stored value's factory setting is its spec's initial value
(:func:`pkwbus.sim.drives.descriptions.factory_raw`); :meth:`ParameterStore.changed`
tells whether a parameter now differs from it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from pkwbus.errors import PkwbusError
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw import PkwRequest, PkwResponse, Width
from pkwbus.protocol.pkw.descriptions import form_of
from pkwbus.protocol.pkw.dialects import WRITE_COMMANDS, Command, Dialect, Reply
from pkwbus.protocol.values import ValueType, decode_value, encode_value
from pkwbus.sim.drives import descriptions
from pkwbus.sim.drives.descriptions import TYPE_CODES
from pkwbus.sim.drives.table import ParamSpec

__all__ = [
    "ARRAY_COMMANDS",
    "EEPROM_COMMANDS",
    "TYPE_CODES",
    "Ahead",
    "FaultNumbers",
    "Live",
    "ParameterStore",
    "Refused",
]

Live = Callable[[str, int], float]
# Parameters answered ahead of the store (a log the model keeps in types the table has not,
# :mod:`pkwbus.sim.drives.profidrive_buffer`): the answer, None for one it does not hold.
Ahead = Callable[[PkwRequest], PkwResponse | None]

EEPROM_COMMANDS = frozenset(
    {
        Command.WRITE_WORD_EEPROM,
        Command.WRITE_DWORD_EEPROM,
        Command.WRITE_ARRAY_WORD_EEPROM,
        Command.WRITE_ARRAY_DWORD_EEPROM,
    }
)
ARRAY_COMMANDS = frozenset(
    {
        Command.READ_ARRAY,
        Command.WRITE_ARRAY_WORD,
        Command.WRITE_ARRAY_DWORD,
        Command.WRITE_ARRAY_WORD_EEPROM,
        Command.WRITE_ARRAY_DWORD_EEPROM,
    }
)


@dataclass(frozen=True, slots=True)
class FaultNumbers:
    """The dialect's fault number for each reason a simulated drive refuses."""

    no_text: int
    no_description: int
    channel: int
    unsupported: int
    illegal_pnu: int = 0
    read_only: int = 1
    limit: int = 2
    subindex: int = 3
    not_array: int = 4
    data_type: int = 5
    not_now: int = 17  # FC prints it as 0x11

    @classmethod
    def of(cls, dialect: Dialect) -> FaultNumbers:
        if dialect.name in ("fc", "danfoss-pcv"):
            return cls(no_text=15, no_description=9, channel=18, unsupported=18)
        return cls(no_text=106, no_description=106, channel=102, unsupported=106)


class Refused(PkwbusError):
    """A request the drive rejects, with the fault number to send."""

    def __init__(self, fault: int) -> None:
        super().__init__(fault)
        self.fault = fault


class ParameterStore:
    """Values (raw numbers as on the wire), texts, EEPROM copies; live ones read the model.

    ``described``: False for a drive that answers every description request (AK 4)
    with the dialect's "description not available" fault.
    """

    def __init__(
        self, specs: Iterable[ParamSpec], dialect: Dialect, live: Live, *, described: bool = True
    ) -> None:
        self.specs = {s.pnu: s for s in specs}
        self.dialect = dialect
        self.described = described
        self.faults = FaultNumbers.of(dialect)
        self.live = live
        self.raw: dict[tuple[int, int], int] = {}
        self.texts: dict[int, bytes] = {}
        self.eeprom: dict[tuple[int, int], int | bytes] = {}
        self.running: Callable[[], bool] = lambda: False
        self.ahead: Ahead | None = None
        for spec in self.specs.values():
            self._initialise(spec)

    def _initialise(self, spec: ParamSpec) -> None:
        if spec.live is not None:
            return
        if spec.vtype is ValueType.TEXT:
            self.texts[spec.pnu] = str(spec.initial).encode("latin-1")
            return
        for index in _stored(spec):
            factory = descriptions.factory_raw(spec, index)
            assert isinstance(factory, int)  # a number: not a text
            self.raw[spec.pnu, index] = factory

    def changed(self, pnu: int) -> bool:
        """Whether a stored parameter (any element, a text) differs from its factory
        setting now; a live value never does."""
        spec = self.specs[pnu]
        if spec.live is not None:
            return False
        if spec.vtype is ValueType.TEXT:
            return self.texts[pnu] != descriptions.factory_raw(spec)
        return any(
            self.raw[pnu, index] != descriptions.factory_raw(spec, index) for index in _stored(spec)
        )

    def keypad(self, pnu: int, raw: int, index: int = 0) -> None:
        """Set element ``index`` of ``pnu`` to ``raw`` (the number on the wire, a float's
        bits) as a person at the drive's keypad (LCP) does: in RAM and EEPROM, with no
        telegram. ValueError with a plain message for a parameter the drive does not have,
        one the keypad cannot set (read-only, a live value, a text), an index it does not
        have, a number its type cannot carry, a value outside its limits, or one that
        cannot change while the motor runs."""
        spec = self.specs.get(pnu)
        if spec is None:
            raise ValueError(f"the drive has no parameter {pnu}")
        what = f"parameter {pnu} ({spec.name})"
        if spec.live is not None or not spec.writable:
            raise ValueError(f"{what} is read-only")
        if spec.vtype is ValueType.TEXT:
            raise ValueError(f"{what} is a text: the keypad sets numbers here")
        if not 0 <= index < spec.elements:
            raise ValueError(f"{what} has no index {index} (0-{spec.elements - 1})")
        width = spec.vtype.width or Width.DWORD
        if not 0 <= raw < 1 << width.value:
            raise ValueError(f"{what}: raw {raw} does not fit {width.value} bits")
        number = float(decode_value(raw, width, spec.vtype, spec.scaling))
        if number != number:
            raise ValueError(f"{what}: raw {raw:#x} is not a number")
        if _outside(spec, number):
            raise ValueError(f"{what}: {number:g} is outside {_limits_text(spec)}")
        if spec.stopped_only and self.running():
            raise ValueError(f"{what} cannot be changed while the motor runs")
        self.raw[pnu, index] = raw
        self.eeprom[pnu, index] = raw

    # ------------------------------------------------------------ values

    def value(self, pnu: int, index: int = 0) -> int:
        spec = self.specs[pnu]
        if spec.live is not None:
            reading = self.live(spec.live, index) * spec.unit_factor
            return encode_value(_clamp(spec, reading), spec.vtype, spec.scaling)
        return self.raw[pnu, index]

    def number(self, pnu: int, index: int = 0) -> float:
        """The engineering value of a numeric parameter."""
        spec = self.specs[pnu]
        width = spec.vtype.width or Width.DWORD
        return float(decode_value(self.value(pnu, index), width, spec.vtype, spec.scaling))

    # ---------------------------------------------------------- requests

    def execute(self, req: PkwRequest) -> PkwResponse:
        """What the drive answers to ``req`` (a write is applied first)."""
        if self.ahead is not None and (answer := self.ahead(req)) is not None:
            return answer
        try:
            return self._execute(req)
        except Refused as refused:
            ak = pkw.response_id(self.dialect, Reply.REJECTED)
            fault = self.dialect.fault(refused.fault)
            return pkw.Rejection(ak, req.pnu, req.subindex, refused.fault, fault.text, fault.short)

    def _execute(self, req: PkwRequest) -> PkwResponse:
        command = req.command
        if command is Command.NONE:
            return pkw.NoResponse(pkw.response_id(self.dialect, Reply.NONE), req.pnu, req.subindex)
        spec = self.specs.get(req.pnu)
        if spec is None:
            raise Refused(self.faults.illegal_pnu)
        if command is Command.TEXT:
            return self._text(spec, req)
        if command is Command.READ_ARRAY_COUNT:
            if not spec.array:
                raise Refused(self.faults.not_array)
            return self._reply(Reply.ARRAY_COUNT, req, spec.array, Width.WORD)
        if command is Command.READ_DESCRIPTION:
            return self._description(spec, req)
        if command is Command.WRITE_DESCRIPTION:
            raise Refused(7 if self.dialect.name != "fc" else self.faults.unsupported)
        if spec.vtype is ValueType.TEXT:
            raise Refused(self.faults.data_type)
        self._check_index(spec, req.subindex)
        if command in WRITE_COMMANDS:
            self._write(spec, req)
        width = spec.vtype.width or Width.DWORD
        raw = self.value(spec.pnu, req.subindex)
        return self._reply(_value_reply(width, command in ARRAY_COMMANDS), req, raw, width)

    def _reply(self, reply: Reply, req: PkwRequest, raw: int, width: Width) -> PkwResponse:
        ak = pkw.response_id(self.dialect, reply)
        if reply is Reply.ARRAY_COUNT:
            return pkw.ArrayCountResponse(ak, req.pnu, req.subindex, raw)
        return pkw.ValueResponse(ak, req.pnu, req.subindex, raw, width)

    def _check_index(self, spec: ParamSpec, subindex: int) -> None:
        if not spec.array and subindex:
            raise Refused(self.faults.not_array)
        if subindex >= spec.elements:
            raise Refused(self.faults.subindex)

    def _write(self, spec: ParamSpec, req: PkwRequest) -> None:
        if not spec.writable or spec.live is not None:
            raise Refused(self.faults.read_only)
        if req.width is not spec.vtype.width:
            raise Refused(self.faults.data_type)
        if spec.stopped_only and self.running():
            raise Refused(self.faults.not_now)
        number = float(decode_value(req.value, req.width, spec.vtype, spec.scaling))
        if _outside(spec, number):
            raise Refused(self.faults.limit)
        self.raw[spec.pnu, req.subindex] = req.value
        if req.command in EEPROM_COMMANDS:
            self.eeprom[spec.pnu, req.subindex] = req.value

    def _text(self, spec: ParamSpec, req: PkwRequest) -> PkwResponse:
        if spec.vtype is not ValueType.TEXT:
            raise Refused(self.faults.no_text)
        if req.text:
            if not spec.writable:
                raise Refused(self.faults.read_only)
            self.texts[spec.pnu] = req.text
            self.eeprom[spec.pnu, 0] = req.text
        ak = pkw.response_id(self.dialect, Reply.TEXT)
        return pkw.TextResponse(ak, req.pnu, req.subindex, self.texts[spec.pnu])

    def _description(self, spec: ParamSpec, req: PkwRequest) -> PkwResponse:
        """Element ``req.subindex`` in the form of the drive's dialect
        (:mod:`pkwbus.sim.drives.descriptions`); refused by a drive or a parameter that has no
        description, and for an element the parameter does not have."""
        form = form_of(self.dialect)
        if form is None or not (self.described and spec.described):
            raise Refused(self.faults.no_description)
        text_length = len(self.texts.get(spec.pnu, b""))
        found = descriptions.element(
            spec, req.subindex, form, text_length=text_length, changed=self.changed(spec.pnu)
        )
        if found is None:
            raise Refused(self.faults.no_description)
        ak = pkw.response_id(self.dialect, Reply.DESCRIPTION)
        return pkw.DescriptionResponse(
            ak, req.pnu, req.subindex, found.raw, found.data, found.width
        )


def _value_reply(width: Width, array: bool) -> Reply:
    if width is Width.WORD:
        return Reply.ARRAY_WORD if array else Reply.WORD
    return Reply.ARRAY_DWORD if array else Reply.DWORD


def _stored(spec: ParamSpec) -> range:
    """The indexes a stored number has: an initial tuple's, else every element."""
    initial = spec.initial
    return range(len(initial) if isinstance(initial, tuple) else spec.elements)


def _outside(spec: ParamSpec, number: float) -> bool:
    """Whether ``number`` is outside the parameter's limits (NaN is outside every one)."""
    too_low = spec.minimum is not None and number < spec.minimum
    too_high = spec.maximum is not None and number > spec.maximum
    return too_low or too_high or number != number


def _limits_text(spec: ParamSpec) -> str:
    low = "" if spec.minimum is None else f"{spec.minimum:g}"
    high = "" if spec.maximum is None else f"{spec.maximum:g}"
    unit = f" {spec.unit}" if spec.unit else ""
    return f"its limits {low}..{high}{unit}"


def _clamp(spec: ParamSpec, reading: float) -> float:
    """A live reading held inside what the parameter's integer type can carry."""
    if spec.vtype is ValueType.F32:
        return reading
    low, high = spec.vtype.bounds
    factor = float(spec.scaling.factor)
    return min(high * factor, max(low * factor, reading))
