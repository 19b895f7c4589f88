"""Reading a GSD file's statements into a :class:`~pkwbus.protocol.profibus.gsd.model.Gsd`.

Blocks (PROFIBUS GSD specification): ``Module`` ... ``EndModule`` (its
reference number may stand alone on a line of its own, its own
``Ext_User_Prm_Data_Const/Ref`` and ``Data_Area_Beg`` ... ``Data_Area_End``
inside), ``PrmText`` ... ``EndPrmText``, ``ExtUserPrmData`` ...
``EndExtUserPrmData``, ``Unit_Diag_Area`` ... ``Unit_Diag_Area_End``, and any
other block whose end the file marks as ``End<Keyword>``, ``End_<Keyword>``
or ``<Keyword>_End`` (``SlotDefinition``, ``UnitDiagType``,
``Physical_Interface``, ``Jokerblock_Type``, ...): read past as a whole.

A keyword this reader does not use is ignored, never refused. What it uses
and cannot read is a :class:`GsdError` naming the line: the ident number, the
user parameter data, ``MaxTsdr``, the DP-V1 keys. A module that cannot be
read, a line that is no statement, a block end without its beginning, are
read past and told in ``warnings``.
"""

from __future__ import annotations

import bisect
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from pkwbus.protocol.profibus.dpv1.msac import DEFAULT_MAX_DATA, DEFAULT_RESPONSE_TIMEOUT, Dpv1Setup
from pkwbus.protocol.profibus.gsd.lines import (
    Bare,
    GsdError,
    Setting,
    Statement,
    byte_list,
    number,
    quoted,
    statements,
)
from pkwbus.protocol.profibus.gsd.model import (
    BAUD_SUFFIXES,
    Gsd,
    GsdModule,
    SlaveFamily,
    UnitDiagArea,
)
from pkwbus.protocol.profibus.gsd.prm import (
    MAX_USER_PRM,
    ExtUserPrm,
    PrmLayout,
    ext_user_prm,
    prm_offset,
)

__all__ = ["parse"]

# Blocks this reader reads, and the line that ends each.
_ENDS = {
    "module": "endmodule",
    "prmtext": "endprmtext",
    "extuserprmdata": "endextuserprmdata",
    "unit_diag_area": "unit_diag_area_end",
}
_TEXTS = ("revision", "hardware_release", "software_release", "ordernumber", "info_text",
          "implementation_type", "vendor_name", "model_name")  # fmt: skip
_NUMBERED = re.compile(r"^[+-]?(0x[0-9a-f]+|\d+)$", re.IGNORECASE)


@dataclass
class _Found:
    values: dict[str, Setting] = field(default_factory=dict)
    max_tsdr: dict[int, int] = field(default_factory=dict)
    rates: set[int] = field(default_factory=set)
    defs: dict[int, ExtUserPrm] = field(default_factory=dict)
    bad_defs: dict[int, GsdError] = field(default_factory=dict)
    texts: dict[int, dict[int, str]] = field(default_factory=dict)
    layout: PrmLayout = field(default_factory=PrmLayout)
    modules: list[tuple[Setting, str, bytes, PrmLayout, int | None, int, str]] = field(
        default_factory=list
    )  # (header, name, cfg, layout, reference, prm length, info)
    unit_diag: dict[int, str] = field(default_factory=dict)
    areas: list[UnitDiagArea] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def warn(self, line: int, text: str) -> None:
        self.warnings.append(f"line {line}: {text}" if line else text)


def parse(text: str) -> Gsd:
    """Read a GSD file's text; a :class:`GsdError` naming the line for what cannot be read."""
    items = statements(text)
    found = _Found()
    _walk(items, found)
    return _build(found)


class _Ends:
    """Where each line without ``=`` stands, to find a block's end without a search."""

    def __init__(self, items: list[Statement]) -> None:
        self.at: dict[str, list[int]] = {}
        for i, item in enumerate(items):
            if isinstance(item, Bare):
                self.at.setdefault(item.text.casefold(), []).append(i)

    def after(self, start: int, markers: tuple[str, ...]) -> int | None:
        """The index of the first line after ``start`` that is one of ``markers``."""
        found = [
            places[k]
            for marker in markers
            if (places := self.at.get(marker))
            and (k := bisect.bisect_right(places, start)) < len(places)
        ]
        return min(found, default=None)


def _markers(key: str) -> tuple[str, ...]:
    """The lines that may end a block that ``key`` begins."""
    base = key.removesuffix("_beg")
    return (f"end{key}", f"end_{key}", f"{key}_end", f"{base}_end")


def _walk(items: list[Statement], found: _Found) -> None:
    ends = _Ends(items)
    i = 0
    while i < len(items):
        item = items[i]
        key = item.key
        known = _ENDS.get(key) if isinstance(item, Setting) else None
        end = ends.after(i, (known,) if known else _markers(key))
        if known is not None and end is None:
            raise GsdError(item.line, f"{key} block without its {known} line")
        if end is None:
            _statement(item, found)
            i += 1
            continue
        if isinstance(item, Setting) and known is not None:
            _block(item, items[i + 1 : end], found)
        i = end + 1  # another block (SlotDefinition, UnitDiagType, ...): read past


def _statement(item: Statement, found: _Found) -> None:
    if isinstance(item, Bare):
        found.warn(item.line, f"{item.text[:40]!r} read past (not a statement here)")
        return
    key = item.key
    if key == "ext_user_prm_data_const":
        found.layout.consts.append((item.line, prm_offset(item), _prm_bytes(item)))
    elif key == "ext_user_prm_data_ref":
        found.layout.refs.append((item.line, prm_offset(item), _number(item)))
    elif key.startswith("maxtsdr_"):
        rate = BAUD_SUFFIXES.get(key.removeprefix("maxtsdr_"))
        if rate is not None:
            found.max_tsdr[rate] = _number(item)
    elif key.endswith("_supp") and key.removesuffix("_supp") in BAUD_SUFFIXES:
        if _number(item):
            found.rates.add(BAUD_SUFFIXES[key.removesuffix("_supp")])
    elif key == "unit_diag_bit" and item.argument is not None:
        bit = number(item.argument, item.line, "Unit_Diag_Bit")
        found.unit_diag.setdefault(bit, _text(item.value))
    else:
        found.values.setdefault(key, item)


def _block(header: Setting, body: list[Statement], found: _Found) -> None:
    key = header.key
    if key == "module":
        _module(header, body, found)
    elif key == "prmtext":
        number_ = _number(header)
        texts = found.texts.setdefault(number_, {})
        for item in body:
            if isinstance(item, Setting) and item.key == "text" and item.argument is not None:
                texts[number(item.argument, item.line, "Text")] = _text(item.value)
    elif key == "extuserprmdata":
        try:
            prm = ext_user_prm(header, body)
        except GsdError as exc:  # an error only where a Ref uses it
            reference = header.value.split(None, 1)[0] if header.value else ""
            if _NUMBERED.match(reference):
                found.bad_defs[number(reference, header.line)] = exc
            found.warn(exc.line, exc.reason)
            return
        found.defs[prm.reference] = prm
    elif key == "unit_diag_area":
        first, _, last = header.value.partition("-")
        values = {
            number(item.argument, item.line, "Value"): _text(item.value)
            for item in body
            if isinstance(item, Setting) and item.key == "value" and item.argument is not None
        }
        low, high = number(first, header.line), number(last or first, header.line)
        found.areas.append(UnitDiagArea(low, high, MappingProxyType(values)))


def _module(header: Setting, body: list[Statement], found: _Found) -> None:
    """A ``Module`` block; one that cannot be read is read past, told in the warnings."""
    line = header.line
    nested = next((i for i in body if isinstance(i, Setting) and i.key == "module"), None)
    if nested is not None:
        raise GsdError(nested.line, f"Module inside module (line {line}: its EndModule is missing)")
    try:
        name, rest = quoted(header.value, line, "Module")
        cfg = byte_list(rest, line, f"module {name!r}")
        if not cfg:
            raise GsdError(line, f"module {name!r} has no configuration bytes")
        layout, reference, length, info = _module_body(body)
    except GsdError as exc:
        found.warn(exc.line, f"{exc.reason}: module read past")
        return
    found.modules.append((header, name, cfg, layout, reference, length, info))


def _module_body(body: list[Statement]) -> tuple[PrmLayout, int | None, int, str]:
    """(its parameter entries, reference number, Ext_Module_Prm_Data_Len, Info_Text)."""
    layout, reference, length, info = PrmLayout(), None, 0, ""
    ends = _Ends(body)
    i = 0
    while i < len(body):
        item = body[i]
        key = item.key
        if isinstance(item, Bare) and _NUMBERED.match(item.text) and reference is None:
            reference = number(item.text, item.line)
        elif isinstance(item, Setting) and key == "ext_user_prm_data_const":
            layout.consts.append((item.line, prm_offset(item), _prm_bytes(item)))
        elif isinstance(item, Setting) and key == "ext_user_prm_data_ref":
            layout.refs.append((item.line, prm_offset(item), _number(item)))
        elif isinstance(item, Setting) and key == "ext_module_prm_data_len":
            length = _number(item)
            if not 0 <= length <= MAX_USER_PRM:
                raise GsdError(item.line, f"Ext_Module_Prm_Data_Len {length} is outside"
                               f" 0-{MAX_USER_PRM}")  # fmt: skip
        elif isinstance(item, Setting) and key == "info_text":
            info = _text(item.value)
        else:
            end = ends.after(i, _markers(key))
            if end is not None:  # Data_Area_Beg ... Data_Area_End: read past
                i = end
        i += 1
    return layout, reference, length, info


# ------------------------------------------------------------------ the result


def _build(found: _Found) -> Gsd:
    values = found.values
    if "ident_number" not in values:
        raise GsdError(0, "no Ident_Number")
    ident = _number(values["ident_number"])
    if not 0 <= ident <= 0xFFFF:
        raise GsdError(values["ident_number"].line, f"Ident_Number {ident} is not 16 bits")
    for rate in sorted(found.rates - found.max_tsdr.keys()):
        found.warn(0, f"no MaxTsdr for the supported rate {rate}")
    modules = []
    for header, name, cfg, layout, reference, length, info in found.modules:
        try:
            modules.append(GsdModule(name, cfg, _prm(found, layout, length), reference, info))
        except GsdError as exc:
            found.warn(exc.line or header.line, f"module {name!r}: {exc.reason}: read past")
    return Gsd(
        ident,
        _slave_prm(found),
        tuple(modules),
        MappingProxyType(dict(found.max_tsdr)),
        _text(values["vendor_name"].value) if "vendor_name" in values else "",
        _text(values["model_name"].value) if "model_name" in values else "",
        _dpv1(values),
        _optional(values, "gsd_revision"),
        frozenset(found.rates),
        _optional(values, "station_type") or 0,
        _family(values.get("slave_family")),
        bool(_optional(values, "modular_station")),
        _optional(values, "max_module"),
        MappingProxyType({k: _text(values[k].value) for k in _TEXTS if k in values}),
        MappingProxyType(dict(found.defs)),
        MappingProxyType({k: MappingProxyType(v) for k, v in found.texts.items()}),
        MappingProxyType(dict(found.unit_diag)),
        tuple(found.areas),
        tuple(found.warnings),
    )


def _prm(found: _Found, layout: PrmLayout, length: int) -> bytes:
    for line, _, ref in layout.refs:
        if ref in found.bad_defs:
            bad = found.bad_defs[ref]
            raise GsdError(line, f"ExtUserPrmData {ref} (line {bad.line}) {bad.reason}")
    return layout.build(found.defs, length)


def _slave_prm(found: _Found) -> bytes:
    """The slave's own user parameter bytes: the Ext_User_Prm_Data entries where the file
    has them (then User_Prm_Data is not used), else User_Prm_Data padded to its length."""
    values = found.values
    if not found.layout.empty:
        data = _prm(found, found.layout, 0)
    else:
        data = _prm_bytes(values["user_prm_data"]) if "user_prm_data" in values else b""
        length = _optional(values, "user_prm_data_len")
        if length is not None and not 0 <= length <= MAX_USER_PRM:
            line = values["user_prm_data_len"].line
            raise GsdError(line, f"User_Prm_Data_Len {length} is outside 0-{MAX_USER_PRM}")
        if length is not None and length > len(data):
            data = data.ljust(length, b"\x00")
    if len(data) > MAX_USER_PRM:
        raise GsdError(0, f"{len(data)} user parameter bytes (at most {MAX_USER_PRM})")
    return data


def _dpv1(values: Mapping[str, Setting]) -> Dpv1Setup | None:
    """The class 1 services of a ``DPV1_Slave = 1`` (GSD specification for DP-V1:
    ``C1_Max_Data_Len`` in bytes, ``C1_Response_Timeout`` in units of 10 ms)."""
    if not _optional(values, "dpv1_slave"):
        return None
    max_data = _optional(values, "c1_max_data_len")
    if max_data is None:
        max_data = DEFAULT_MAX_DATA
    elif not 0 <= max_data <= DEFAULT_MAX_DATA:
        line = values["c1_max_data_len"].line
        raise GsdError(line, f"C1_Max_Data_Len {max_data} is outside 0-{DEFAULT_MAX_DATA}")
    ticks = _optional(values, "c1_response_timeout")
    if ticks is None:
        ticks = round(DEFAULT_RESPONSE_TIMEOUT / 0.01)
    elif not 1 <= ticks <= 0xFFFF:
        line = values["c1_response_timeout"].line
        raise GsdError(line, f"C1_Response_Timeout {ticks} is outside 1-65535")
    return Dpv1Setup(max_data, ticks * 0.01, bool(_optional(values, "c1_read_write_supp")))


def _family(setting: Setting | None) -> SlaveFamily | None:
    if setting is None:
        return None
    main, *subs = setting.value.split("@")
    return SlaveFamily(number(main, setting.line, "Slave_Family"), tuple(s.strip() for s in subs))


def _optional(values: Mapping[str, Setting], key: str) -> int | None:
    return _number(values[key]) if key in values else None


def _number(setting: Setting) -> int:
    return number(setting.value, setting.line, setting.key)


def _prm_bytes(setting: Setting) -> bytes:
    return byte_list(setting.value, setting.line, setting.key)


def _text(value: str) -> str:
    """A quoted text's content; an unquoted value as it stands."""
    value = value.strip()
    if value.startswith('"'):
        end = value.find('"', 1)
        return value[1:end] if end > 0 else value[1:]
    return value
