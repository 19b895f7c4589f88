"""A GSD file's user parameters: the ``ExtUserPrmData`` definitions and the bytes their
defaults make (PROFIBUS GSD specification, "Ext_User_Prm_Data").

``Ext_User_Prm_Data_Const(offset) = bytes`` puts fixed bytes at an offset;
``Ext_User_Prm_Data_Ref(offset) = n`` puts the default of definition ``n``
there (a ``Bit(b)`` or ``BitArea(first-last)`` into its bits of that byte,
an ``Unsigned8/16/32`` or ``Signed8/16/32`` big-endian); consts first, refs
over them, in file order. Where a file has neither, its ``User_Prm_Data``
(padded with zeros to ``User_Prm_Data_Len``) is the slave's user parameter
data. Pure: statements in, bytes out.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType

from pkwbus.protocol.profibus.gsd.lines import Bare, GsdError, Setting, Statement, number, quoted

__all__ = ["MAX_USER_PRM", "ExtUserPrm", "PrmLayout", "ext_user_prm", "prm_offset"]

MAX_USER_PRM = 237  # user parameter bytes a Set_Prm carries at most (244 - 7)

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
_TYPE_LINE = re.compile(
    r"^(\w+)\s*(?:\(\s*(\w+)\s*(?:-\s*(\w+))?\s*\))?\s+([+-]?\w+)\s*(.*)$", re.IGNORECASE
)
_RANGE = re.compile(r"^([+-]?\w+)\s*-\s*([+-]?\w+)$")


@dataclass(frozen=True, slots=True)
class ExtUserPrm:
    """An ``ExtUserPrmData`` definition: where its default goes and how wide it is."""

    reference: int
    name: str
    default: int
    size: int  # bytes for a whole-byte type; 1 for a bit field
    bits: tuple[int, int] | None = None  # (first, last) bit for Bit/BitArea
    signed: bool = False
    allowed: tuple[int, ...] | None = None  # a range (low, high) or a set of values
    is_range: bool = False
    text_ref: int | None = None  # its PrmText's number
    changeable: bool = True
    visible: bool = True

    @property
    def type_name(self) -> str:
        if self.bits is None:
            kind = "Signed" if self.signed else "Unsigned"
            return f"{kind}{8 * self.size}"
        first, last = self.bits
        return f"Bit({first})" if first == last else f"BitArea({first}-{last})"


@dataclass
class PrmLayout:
    """Const and Ref entries (of the slave, or of one module), in file order."""

    consts: list[tuple[int, int, bytes]] = field(default_factory=list)  # (line, offset, bytes)
    refs: list[tuple[int, int, int]] = field(default_factory=list)  # (line, offset, reference)

    @property
    def empty(self) -> bool:
        return not self.consts and not self.refs

    def build(self, defs: Mapping[int, ExtUserPrm], length: int = 0) -> bytes:
        """The bytes the entries make, at least ``length`` long (zeros where none is set)."""
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


def prm_offset(setting: Setting) -> int:
    """The byte offset in parentheses of an ``Ext_User_Prm_Data_Const/Ref``."""
    if not setting.argument:
        raise GsdError(setting.line, "the byte offset in parentheses is missing")
    offset = number(setting.argument, setting.line, "byte offset")
    if not 0 <= offset < MAX_USER_PRM:
        raise GsdError(setting.line, f"byte offset {offset} is outside 0-{MAX_USER_PRM - 1}")
    return offset


def ext_user_prm(header: Setting, body: list[Statement]) -> ExtUserPrm:
    """An ``ExtUserPrmData = n "name"`` block: its data type line (``Unsigned8 2 0-5``,
    ``Bit(3) 1 0-1``, ``BitArea(4-6) 5 0-7``, ``Unsigned8 1 1,2,4``) and its settings
    (``Prm_Text_Ref``, ``Changeable``, ``Visible``)."""
    line = header.line
    reference_text, _, rest = header.value.partition(" ")
    reference = number(reference_text, line, "ExtUserPrmData")
    name, _ = quoted(rest.strip(), line, "ExtUserPrmData") if rest.strip() else ("", "")
    spec = next((s for s in body if isinstance(s, Bare)), None)
    if spec is None:
        raise GsdError(line, f"ExtUserPrmData {reference} has no data type line")
    prm = _data_type(reference, name, spec)
    for setting in body:
        if not isinstance(setting, Setting):
            continue
        if setting.key == "prm_text_ref":
            prm = replace(prm, text_ref=number(setting.value, setting.line, "Prm_Text_Ref"))
        elif setting.key == "changeable":
            prm = replace(prm, changeable=number(setting.value, setting.line, "Changeable") != 0)
        elif setting.key == "visible":
            prm = replace(prm, visible=number(setting.value, setting.line, "Visible") != 0)
    return prm


def _data_type(reference: int, name: str, spec: Bare) -> ExtUserPrm:
    line = spec.line
    match = _TYPE_LINE.match(spec.text)
    if match is None:
        raise GsdError(line, f"cannot read the data type line {spec.text[:40]!r}")
    kind_text, first_text, last_text, default_text, allowed_text = match.groups()
    kind = kind_text.casefold()
    default = number(default_text, line, "default")
    allowed, is_range = _allowed(allowed_text.strip(), line)
    if kind in ("bit", "bitarea"):
        if first_text is None:
            raise GsdError(line, f"{kind_text} needs a bit number")
        first = number(first_text, line, "bit")
        last = number(last_text, line, "bit") if last_text is not None else first
        if not 0 <= first <= last <= 7:
            raise GsdError(line, f"bits {first}-{last} are outside 0-7")
        if not 0 <= default < 1 << (last - first + 1):
            raise GsdError(line, f"default {default} does not fit bits {first}-{last}")
        return ExtUserPrm(reference, name, default, 1, (first, last), False, allowed, is_range)
    if kind not in _TYPES:
        raise GsdError(line, f"unknown data type {kind_text!r}")
    size, signed = _TYPES[kind]
    bits = 8 * size
    low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    if not low <= default <= high:
        raise GsdError(line, f"default {default} does not fit {kind_text}")
    return ExtUserPrm(reference, name, default, size, None, signed, allowed, is_range)


def _allowed(text: str, line: int) -> tuple[tuple[int, ...] | None, bool]:
    if not text:
        return None, False
    match = _RANGE.match(text)
    if match is not None:
        return (number(match.group(1), line, "range"), number(match.group(2), line, "range")), True
    values = [v for v in re.split(r"[,\s]+", text) if v]
    return tuple(number(v, line, "allowed value") for v in values), False
