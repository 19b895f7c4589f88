"""The PKW dialects of the manuals, and their lookup by name.

fc (Danfoss VLT Design Manual, section 8.4.7 "The PKE Field"), uss and
profidrive (Siemens SINAMICS G120 CU240B-2/CU240E-2 Operating Instructions
07/2010, section 6.3 "Communication via PROFIBUS"), danfoss-pcv (Danfoss
PROFIBUS manual, section 5.3.4 "RC Content"), hitachi-sjpb (Hitachi SJ-PB(T)
User Manual, chapter 5 "Operating"). Each is built from its tables in
:mod:`pkwbus.protocol.pkw.dialects.tables` on the type of
:mod:`pkwbus.protocol.pkw.dialects.model`, whose names this module re-exports.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` from :func:`dialect`
for an unknown name (and, through :class:`Dialect`, for what a dialect cannot
encode).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects.model import (
    DWORD_COMMANDS,
    NEGATIVE_REPLIES,
    VALUE_REPLIES,
    WRITE_COMMANDS,
    Command,
    Dialect,
    Fault,
    IndLayout,
    Reply,
)
from pkwbus.protocol.pkw.dialects.tables import (
    FC_ARRAY_ALIASES,
    FC_FAULTS,
    FC_REQUESTS,
    FC_RESPONSES,
    HITACHI_FAULTS,
    HITACHI_REQUESTS,
    HITACHI_RESPONSES,
    PCV_FAULTS,
    PCV_REQUESTS,
    PCV_RESPONSES,
    SIEMENS_FAULTS,
    SIEMENS_REQUESTS,
    SIEMENS_RESPONSES,
)

__all__ = [
    "DANFOSS_PCV",
    "DIALECTS",
    "DWORD_COMMANDS",
    "FC",
    "HITACHI_SJPB",
    "NEGATIVE_REPLIES",
    "PROFIDRIVE",
    "USS",
    "VALUE_REPLIES",
    "WRITE_COMMANDS",
    "Command",
    "Dialect",
    "Fault",
    "IndLayout",
    "Reply",
    "dialect",
]


class _FcDialect(Dialect):
    """FC: array elements use the ordinary identifiers with the index in IND."""

    def request_id(self, command: Command) -> int:
        alias = FC_ARRAY_ALIASES.get(command)
        return alias if alias is not None else Dialect.request_id(self, command)

    def has(self, command: Command) -> bool:
        return command in FC_ARRAY_ALIASES or Dialect.has(self, command)


FC = _FcDialect(
    name="fc",
    title="Danfoss FC protocol",
    pnu_bits=12,
    page_index=False,
    default_ind_layout=IndLayout.USS,
    requests=FC_REQUESTS,
    responses=FC_RESPONSES,
    faults=FC_FAULTS,
    text_ind_high=(0x04, 0x05),
    danfoss_numbers=True,
)
USS = Dialect(
    name="uss",
    title="Siemens USS",
    pnu_bits=11,
    page_index=True,
    default_ind_layout=IndLayout.USS,
    requests=SIEMENS_REQUESTS,
    responses=SIEMENS_RESPONSES,
    faults=SIEMENS_FAULTS,
)
PROFIDRIVE = Dialect(
    name="profidrive",
    title="PROFIdrive parameter channel (Siemens)",
    pnu_bits=11,
    page_index=True,
    default_ind_layout=IndLayout.PROFIDRIVE,
    requests=SIEMENS_REQUESTS,
    responses=SIEMENS_RESPONSES,
    faults=SIEMENS_FAULTS,
)
DANFOSS_PCV = Dialect(
    name="danfoss-pcv",
    title="Danfoss PROFIBUS PCV",
    pnu_bits=11,
    page_index=False,
    default_ind_layout=IndLayout.PROFIDRIVE,
    requests=PCV_REQUESTS,
    responses=PCV_RESPONSES,
    faults=PCV_FAULTS,
    danfoss_numbers=True,
)
HITACHI_SJPB = Dialect(
    name="hitachi-sjpb",
    title="Hitachi SJ-PB(T)",
    pnu_bits=11,
    page_index=False,
    default_ind_layout=IndLayout.PROFIDRIVE,
    requests=HITACHI_REQUESTS,
    responses=HITACHI_RESPONSES,
    faults=HITACHI_FAULTS,
)

DIALECTS: Mapping[str, Dialect] = MappingProxyType(
    {d.name: d for d in (FC, USS, PROFIDRIVE, DANFOSS_PCV, HITACHI_SJPB)}
)


def dialect(name: str) -> Dialect:
    try:
        return DIALECTS[name]
    except KeyError:
        known = ", ".join(DIALECTS)
        raise LocalProtocolError(f"unknown dialect {name!r} (known: {known})") from None
