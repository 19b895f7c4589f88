"""Reading a slave's GSD file (the text "device data base" every PROFIBUS vendor publishes).

What a DP master needs from it: the ident number, the user parameter
bytes with their defaults (``User_Prm_Data``, or ``Ext_User_Prm_Data_Const``
and ``Ext_User_Prm_Data_Ref`` with the ``ExtUserPrmData`` definitions), the
modules with their configuration identifiers, and ``MaxTsdr`` per baud rate
and, of a DP-V1 slave, its class 1 services (:func:`_dpv1`)
(PROFIBUS GSD specification: keywords are case-insensitive, ``;`` starts a
comment, ``\\`` at the end of a line continues it). Pure: text in, objects out.

Raises :class:`GsdError` (with the line) for a GSD file that does not parse,
:class:`~pkwbus.protocol.errors.LocalProtocolError` for a module it lacks.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Final

from pkwbus.protocol.dpv1 import DEFAULT_MAX_DATA, DEFAULT_RESPONSE_TIMEOUT, Dpv1Setup
from pkwbus.protocol.errors import LocalProtocolError

__all__ = ["BAUD_SUFFIXES", "HEADER", "ExtUserPrm", "Gsd", "GsdError", "GsdModule", "parse"]

HEADER: Final = "#profibus_dp"

# MaxTsdr_<rate> keyword suffixes and the baud rate they stand for.
BAUD_SUFFIXES: Mapping[str, int] = MappingProxyType(
    {
        "9.6": 9_600,
        "19.2": 19_200,
        "31.25": 31_250,
        "45.45": 45_450,
        "93.75": 93_750,
        "187.5": 187_500,
        "500": 500_000,
        "1.5m": 1_500_000,
        "3m": 3_000_000,
        "6m": 6_000_000,
        "12m": 12_000_000,
    }
)

_TYPES: Mapping[str, tuple[int, bool]] = MappingProxyType(
    {
        "unsigned8": (1, False),
        "unsigned16": (2, False),
        "unsigned32": (4, False),
        "signed8": (1, True),
        "signed16": (2, True),
        "signed32": (4, True),
    }
)


class GsdError(LocalProtocolError):
    """A GSD file this reader cannot use; ``line`` is where (1-based, 0 for the whole file)."""

    def __init__(self, line: int, message: str) -> None:
        self.line = line
        super().__init__(f"GSD line {line}: {message}" if line else f"GSD: {message}")


@dataclass(frozen=True, slots=True)
class ExtUserPrm:
    """An ``ExtUserPrmData`` definition: where its default goes and how wide it is."""

    reference: int
    name: str
    default: int
    size: int  # bytes for a whole-byte type; 1 for a bit field
    bits: tuple[int, int] | None = None  # (first, last) bit for Bit/BitArea
    signed: bool = False


@dataclass(frozen=True, slots=True)
class GsdModule:
    name: str
    cfg: bytes
    user_prm: bytes = b""  # the module's own parameter bytes (modular slaves)
    reference: int | None = None


@dataclass(frozen=True, slots=True)
class Gsd:
    ident: int
    user_prm: bytes
    modules: tuple[GsdModule, ...]
    max_tsdr: Mapping[int, int] = field(default_factory=dict)  # baud rate -> bit times
    vendor: str = ""
    model: str = ""
    dpv1: Dpv1Setup | None = None  # None: a DP-V0 slave (no ``DPV1_Slave = 1``)

    def module(self, name: str) -> GsdModule:
        """The module of that name (case-insensitive, blanks ignored at the ends)."""
        wanted = name.strip().casefold()
        for module in self.modules:
            if module.name.strip().casefold() == wanted:
                return module
        known = ", ".join(repr(m.name) for m in self.modules) or "none"
        raise LocalProtocolError(f"the GSD has no module {name!r} (modules: {known})")

    def prm_for(self, modules: Sequence[GsdModule] = ()) -> bytes:
        """User parameter bytes for a configuration: the slave's, then each module's own."""
        return self.user_prm + b"".join(m.user_prm for m in modules)


# --------------------------------------------------------------------- lines


def _logical_lines(text: str) -> list[tuple[int, str]]:
    """(first line number, text) with comments removed and continuations joined."""
    out: list[tuple[int, str]] = []
    pending = ""
    start = 0
    for number, raw in enumerate(text.splitlines(), 1):
        line = _strip_comment(raw).rstrip()
        if not pending:
            start = number
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        full = (pending + line).strip()
        pending = ""
        if full:
            out.append((start, full))
    if pending.strip():
        out.append((start, pending.strip()))
    return out


def _strip_comment(line: str) -> str:
    quoted = False
    for i, char in enumerate(line):
        if char == '"':
            quoted = not quoted
        elif char == ";" and not quoted:
            return line[:i]
    return line


def _number(token: str, line: int) -> int:
    token = token.strip()
    try:
        if token.lower().startswith("0x"):
            return int(token[2:], 16)
        return int(token, 10)
    except ValueError:
        raise GsdError(line, f"{token!r} is not a number") from None


def _byte_list(value: str, line: int) -> bytes:
    items = [v for v in re.split(r"[,\s]+", value.strip()) if v]
    numbers = [_number(v, line) for v in items]
    bad = [n for n in numbers if not 0 <= n <= 255]
    if bad:
        raise GsdError(line, f"{bad[0]} is not a byte")
    return bytes(numbers)


_KEY = re.compile(r"^([A-Za-z_][\w.]*)\s*(?:\(\s*([^)]*)\s*\))?\s*=\s*(.*)$")
_QUOTED = re.compile(r'^"([^"]*)"\s*(.*)$')


def _split(line: str, number: int) -> tuple[str, str | None, str]:
    match = _KEY.match(line)
    if match is None:
        raise GsdError(number, f"cannot read {line[:40]!r} (expected Keyword = value)")
    return match.group(1).casefold(), match.group(2), match.group(3).strip()


def _quoted(value: str, number: int) -> tuple[str, str]:
    match = _QUOTED.match(value)
    if match is None:
        raise GsdError(number, f"expected a quoted name in {value[:40]!r}")
    return match.group(1), match.group(2)


# ------------------------------------------------------------------- parsing


@dataclass
class _Prm:
    """Const and Ref entries (global or of one module), in file order."""

    consts: list[tuple[int, int, bytes]] = field(default_factory=list)  # (line, offset, bytes)
    refs: list[tuple[int, int, int]] = field(default_factory=list)  # (line, offset, reference)

    def build(self, defs: Mapping[int, ExtUserPrm], length: int, plain: bytes) -> bytes:
        if not self.consts and not self.refs:
            return plain.ljust(length, b"\x00")
        ends = [off + len(data) for _, off, data in self.consts]
        for line, off, ref in self.refs:
            if ref not in defs:
                raise GsdError(line, f"Ext_User_Prm_Data_Ref names undefined ExtUserPrmData {ref}")
            ends.append(off + defs[ref].size)
        out = bytearray(max([length, *ends]))
        for _, off, data in self.consts:
            out[off : off + len(data)] = data
        for _, off, ref in self.refs:
            _place(out, off, defs[ref])
        return bytes(out)


def _place(out: bytearray, offset: int, prm: ExtUserPrm) -> None:
    if prm.bits is not None:
        first, last = prm.bits
        mask = ((1 << (last - first + 1)) - 1) << first
        out[offset] = (out[offset] & ~mask & 0xFF) | (prm.default << first & mask)
        return
    value = prm.default & ((1 << (8 * prm.size)) - 1)
    out[offset : offset + prm.size] = value.to_bytes(prm.size, "big")


def _ext_def(header: str, body: list[tuple[int, str]], number: int) -> ExtUserPrm:
    reference_text, rest = header.split(None, 1) if " " in header else (header, "")
    reference = _number(reference_text, number)
    name, _ = _quoted(rest.strip(), number)
    if not body:
        raise GsdError(number, f"ExtUserPrmData {reference} has no data type line")
    line_no, spec = body[0]
    match = re.match(
        r"^(\w+)\s*(?:\(\s*(\d+)\s*(?:-\s*(\d+))?\s*\))?\s+(-?\w+)", spec, re.IGNORECASE
    )
    if match is None:
        raise GsdError(line_no, f"cannot read the data type line {spec[:40]!r}")
    kind = match.group(1).casefold()
    default = _number(match.group(4), line_no)
    if kind in ("bit", "bitarea"):
        if match.group(2) is None:
            raise GsdError(line_no, f"{match.group(1)} needs a bit number")
        first = int(match.group(2))
        last = int(match.group(3)) if match.group(3) is not None else first
        if not 0 <= first <= last <= 7:
            raise GsdError(line_no, f"bits {first}-{last} are outside 0-7")
        if not 0 <= default < 1 << (last - first + 1):
            raise GsdError(line_no, f"default {default} does not fit bits {first}-{last}")
        return ExtUserPrm(reference, name, default, 1, (first, last))
    if kind not in _TYPES:
        raise GsdError(line_no, f"unknown data type {match.group(1)!r}")
    size, signed = _TYPES[kind]
    low, high = (
        (-(1 << (8 * size - 1)), (1 << (8 * size - 1)) - 1) if signed else (0, (1 << 8 * size) - 1)
    )
    if not low <= default <= high:
        raise GsdError(line_no, f"default {default} does not fit {match.group(1)}")
    return ExtUserPrm(reference, name, default, size, None, signed)


def parse(text: str) -> Gsd:
    """Read a GSD file's text; a :class:`GsdError` naming the line for what cannot be read."""
    lines = _logical_lines(text)
    if not lines or lines[0][1].casefold() != HEADER:
        raise GsdError(lines[0][0] if lines else 0, "not a GSD file (no #Profibus_DP header)")
    values: dict[str, tuple[int, str]] = {}
    max_tsdr: dict[int, int] = {}
    defs: dict[int, ExtUserPrm] = {}
    glob = _Prm()
    modules: list[tuple[int, str, bytes, _Prm, int | None]] = []
    block: tuple[str, int, str, list[tuple[int, str]]] | None = None  # (kind, line, header, body)
    current: tuple[int, str, bytes, _Prm, list[int | None]] | None = None

    for number, line in lines[1:]:
        low = line.casefold()
        if block is not None:
            kind, start, header, body = block
            if low == "end" + kind:
                if kind == "extuserprmdata":
                    prm = _ext_def(header, body, start)
                    defs[prm.reference] = prm
                block = None
            else:
                body.append((number, line))
            continue
        if low == "endmodule":
            if current is None:
                raise GsdError(number, "EndModule without Module")
            modules.append((current[0], current[1], current[2], current[3], current[4][0]))
            current = None
            continue
        if current is not None and re.fullmatch(r"(0x[0-9a-f]+|\d+)", low):
            current[4][0] = _number(line, number)  # the module reference number
            continue
        key, arg, value = _split(line, number)
        if key in ("extuserprmdata", "prmtext"):
            block = (key, number, value, [])
            continue
        if key == "module":
            if current is not None:
                raise GsdError(number, f"Module inside module {current[1]!r} (EndModule missing)")
            name, rest = _quoted(value, number)
            cfg = _byte_list(rest, number)
            if not cfg:
                raise GsdError(number, f"module {name!r} has no configuration bytes")
            current = (number, name, cfg, _Prm(), [None])
            continue
        target = current[3] if current is not None else glob
        if key == "ext_user_prm_data_const":
            target.consts.append((number, _offset(arg, number), _byte_list(value, number)))
        elif key == "ext_user_prm_data_ref":
            target.refs.append((number, _offset(arg, number), _number(value, number)))
        elif key.startswith("maxtsdr_"):
            rate = BAUD_SUFFIXES.get(key.removeprefix("maxtsdr_"))
            if rate is not None:
                max_tsdr[rate] = _number(value, number)
        elif current is None:
            values.setdefault(key, (number, value))
    if block is not None:
        raise GsdError(block[1], f"{block[0]} block without its End line")
    if current is not None:
        raise GsdError(current[0], f"module {current[1]!r} without EndModule")
    return _build(values, max_tsdr, defs, glob, modules)


def _offset(arg: str | None, number: int) -> int:
    if arg is None:
        raise GsdError(number, "the byte offset in parentheses is missing")
    offset = _number(arg, number)
    if not 0 <= offset <= 236:
        raise GsdError(number, f"byte offset {offset} is outside 0-236")
    return offset


def _build(
    values: Mapping[str, tuple[int, str]],
    max_tsdr: dict[int, int],
    defs: Mapping[int, ExtUserPrm],
    glob: _Prm,
    modules: list[tuple[int, str, bytes, _Prm, int | None]],
) -> Gsd:
    if "ident_number" not in values:
        raise GsdError(0, "no Ident_Number")
    line, text = values["ident_number"]
    ident = _number(text, line)
    if not 0 <= ident <= 0xFFFF:
        raise GsdError(line, f"Ident_Number {ident} is not 16 bits")
    length = 0
    if "user_prm_data_len" in values:
        line, text = values["user_prm_data_len"]
        length = _number(text, line)
        if not 0 <= length <= 237:
            raise GsdError(line, f"User_Prm_Data_Len {length} is outside 0-237")
    plain = b""
    if "user_prm_data" in values:
        plain = _byte_list(values["user_prm_data"][1], values["user_prm_data"][0])
    user_prm = glob.build(defs, length, plain)
    if len(user_prm) > 237:
        raise GsdError(0, f"{len(user_prm)} user parameter bytes (at most 237)")
    built = tuple(
        GsdModule(name, cfg, prm.build(defs, 0, b""), ref) for _, name, cfg, prm, ref in modules
    )

    def text_of(key: str) -> str:
        raw = values.get(key, (0, ""))[1]
        return raw.strip('"')

    return Gsd(
        ident,
        user_prm,
        built,
        MappingProxyType(max_tsdr),
        text_of("vendor_name"),
        text_of("model_name"),
        _dpv1(values),
    )


def _dpv1(values: Mapping[str, tuple[int, str]]) -> Dpv1Setup | None:
    """The class 1 services of a ``DPV1_Slave = 1`` (GSD specification for DP-V1:
    ``C1_Max_Data_Len`` in bytes, ``C1_Response_Timeout`` in units of 10 ms)."""

    def number(key: str, default: int) -> int:
        if key not in values:
            return default
        line, text = values[key]
        return _number(text, line)

    if not number("dpv1_slave", 0):
        return None
    max_data = number("c1_max_data_len", DEFAULT_MAX_DATA)
    if not 0 <= max_data <= DEFAULT_MAX_DATA:
        raise GsdError(values["c1_max_data_len"][0], f"C1_Max_Data_Len {max_data} is outside 0-240")
    ticks = number("c1_response_timeout", round(DEFAULT_RESPONSE_TIMEOUT / 0.01))
    if not 1 <= ticks <= 0xFFFF:
        raise GsdError(
            values["c1_response_timeout"][0], f"C1_Response_Timeout {ticks} is outside 1-65535"
        )
    return Dpv1Setup(max_data, ticks * 0.01, bool(number("c1_read_write_supp", 0)))
