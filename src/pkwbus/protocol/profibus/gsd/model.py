"""What a GSD file says of a slave: the objects :func:`pkwbus.protocol.profibus.gsd.parse` returns.

The baud rate keywords and the main slave families are those of the PROFIBUS
GSD specification (``9.6_supp`` ... ``12M_supp``, ``MaxTsdr_9.6`` ...
``MaxTsdr_12M``; ``Slave_Family``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus.dpv1.msac import Dpv1Setup
from pkwbus.protocol.profibus.gsd.prm import MAX_USER_PRM, ExtUserPrm

__all__ = ["BAUD_SUFFIXES", "FAMILIES", "Gsd", "GsdModule", "SlaveFamily", "UnitDiagArea"]

# The rate part of ``<rate>_supp`` and ``MaxTsdr_<rate>`` (casefolded) and the baud rate.
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

# Main slave families (PROFIBUS GSD specification, keyword Slave_Family).
FAMILIES: Mapping[int, str] = MappingProxyType(
    {
        0: "General",
        1: "Drives",
        2: "Switching devices",
        3: "I/O",
        4: "Valves",
        5: "Controllers",
        6: "HMI",
        7: "Encoders",
        8: "NC/RC",
        9: "Gateway",
        10: "Programmable Logic Controllers",
        11: "Ident systems",
        12: "PROFIBUS PA profiles",
    }
)


@dataclass(frozen=True, slots=True)
class SlaveFamily:
    """``Slave_Family = main@sub@sub``: the main family number and the vendor's sub-families."""

    main: int
    sub: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        return FAMILIES.get(self.main, "")


@dataclass(frozen=True, slots=True)
class GsdModule:
    """A ``Module``: its name, configuration identifiers, reference number (where the file
    gives one) and its own user parameter bytes (modular slaves)."""

    name: str
    cfg: bytes
    user_prm: bytes = b""
    reference: int | None = None
    info: str = ""


@dataclass(frozen=True, slots=True)
class UnitDiagArea:
    """``Unit_Diag_Area = first-last`` with its ``Value(n)`` texts."""

    first: int
    last: int
    values: Mapping[int, str]


@dataclass(frozen=True, slots=True)
class Gsd:
    """A slave as its GSD file describes it."""

    ident: int
    user_prm: bytes  # the slave's own user parameter bytes with their defaults
    modules: tuple[GsdModule, ...]
    max_tsdr: Mapping[int, int] = field(default_factory=dict)  # baud rate -> bit times
    vendor: str = ""
    model: str = ""
    dpv1: Dpv1Setup | None = None  # None: a DP-V0 slave (no ``DPV1_Slave = 1``)
    revision: int | None = None  # GSD_Revision
    baud_rates: frozenset[int] = frozenset()  # the rates whose ``_supp`` is 1
    station_type: int = 0  # 0: a DP slave
    family: SlaveFamily | None = None
    modular: bool = False
    max_modules: int | None = None
    texts: Mapping[str, str] = field(default_factory=dict)  # Revision, OrderNumber, ...
    prm_definitions: Mapping[int, ExtUserPrm] = field(default_factory=dict)
    prm_texts: Mapping[int, Mapping[int, str]] = field(default_factory=dict)
    unit_diag: Mapping[int, str] = field(default_factory=dict)  # Unit_Diag_Bit(n) texts
    unit_diag_areas: tuple[UnitDiagArea, ...] = ()
    warnings: tuple[str, ...] = ()  # lines read past (an unknown keyword is not one)

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
        data = self.user_prm + b"".join(m.user_prm for m in modules)
        if len(data) > MAX_USER_PRM:
            raise LocalProtocolError(
                f"{len(data)} user parameter bytes with these modules (at most {MAX_USER_PRM})"
            )
        return data

    def supports(self, baudrate: int) -> bool | None:
        """Whether the file says the slave runs at ``baudrate``; None where it names no
        rate at all (then it says nothing)."""
        if not self.baud_rates:
            return None
        return baudrate in self.baud_rates

    def rates_text(self) -> str:
        return ", ".join(str(rate) for rate in sorted(self.baud_rates)) or "none"
