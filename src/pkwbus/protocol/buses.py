"""The buses pkwbus masters (:class:`Bus`) and what each allows: its drive addresses, its
PKW lengths, its dialects, its status word profiles.

The configuration, the command line, the simulator and the load estimate all
ask here. FC: addresses 1-126 (ADR format 1-126) or 1-31 (format 1-31),
Danfoss FC protocol, telegram structure; USS: 0-30 (ADR bits 0-4 give 0-31,
drives accept 0-30), SINAMICS G120 Operating Instructions, USS; PROFIBUS DP:
0-125 (EN 50170 vol. 2, station addresses).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.length import AUTO, PkwSetting
from pkwbus.protocol.profibus.dp.ppo import DEFAULT_PROFILES
from pkwbus.protocol.pzd import Profile
from pkwbus.protocol.serial.telegram import (
    FC_PARAMETER,
    Address,
    BlockShape,
    FcAddressFormat,
    decode_fc_adr,
    decode_uss_adr,
)

__all__ = [
    "DIALECTS_BY_PROTOCOL",
    "DP_MAX_ADDRESS",
    "FIXED_PKW_WORDS",
    "FIXED_SHAPES",
    "LEARNED_LENGTH",
    "USS_MAX_ADDRESS",
    "VARIABLE_PKW_WORDS",
    "Bus",
    "address_range",
    "check_address",
    "decode_adr",
    "default_dialect",
    "dialect_fits",
    "pkw_setting",
    "pkw_words",
    "profile",
]


class Bus(enum.StrEnum):
    """A line's bus: the ``protocol`` of its configuration."""

    FC = "fc"  # Danfoss FC protocol: serial telegrams
    USS = "uss"  # Siemens USS: serial telegrams
    PROFIBUS = "profibus"  # DP-V0: FDL frames (protocol.fdl), the PKW channel inside PPOs


USS_MAX_ADDRESS: Final = 30
FIXED_PKW_WORDS: Final = (0, 3, 4)  # USS PKW lengths with a fixed number of words
VARIABLE_PKW_WORDS: Final = 127  # the USS code of a variable PKW length

DIALECTS_BY_PROTOCOL: Final = {
    Bus.FC: ("fc",),
    Bus.USS: ("uss", "profidrive", "danfoss-pcv", "hitachi-sjpb"),
    Bus.PROFIBUS: ("profidrive", "danfoss-pcv", "hitachi-sjpb"),
}
DP_MAX_ADDRESS: Final = 125  # DP stations 0-125 (126: commissioning, 127: broadcast)

# The block shape a protocol fixes, whatever is configured: FC, 4 PKW and 2 PZD words
# (Danfoss FC protocol, telegram structure).
FIXED_SHAPES: Final[dict[Bus, BlockShape]] = {Bus.FC: FC_PARAMETER}
# The protocols whose PKW length is learned from the drive's answers (``pkw_words: auto``).
LEARNED_LENGTH: Final = frozenset({Bus.USS})
# The status and control word profile by protocol and dialect (else PROFIdrive).
_PROFILES: Final[dict[Bus, Mapping[str, Profile]]] = {
    Bus.FC: {"fc": Profile.FC},
    Bus.USS: {},
    Bus.PROFIBUS: DEFAULT_PROFILES,
}
_NAMES: Final = {Bus.FC: "FC", Bus.USS: "USS", Bus.PROFIBUS: "DP"}


def address_range(
    protocol: Bus, fc_format: FcAddressFormat = FcAddressFormat.RANGE_1_126
) -> tuple[int, int]:
    """The lowest and highest address a drive of ``protocol`` can have."""
    if protocol is Bus.USS:
        return (0, USS_MAX_ADDRESS)
    if protocol is Bus.PROFIBUS:
        return (0, DP_MAX_ADDRESS)
    return (1, 31) if fc_format is FcAddressFormat.RANGE_1_31 else (1, 126)


def check_address(
    protocol: Bus, address: int, fc_format: FcAddressFormat = FcAddressFormat.RANGE_1_126
) -> None:
    """LocalProtocolError for an address no drive of ``protocol`` can have."""
    low, high = address_range(protocol, fc_format)
    if not low <= address <= high:
        raise LocalProtocolError(f"{_NAMES[protocol]} address {address} is outside {low}-{high}")


def profile(protocol: Bus, dialect_name: str) -> Profile:
    """The profile of the control and status words of a drive of ``protocol`` speaking
    ``dialect_name``."""
    return _PROFILES[protocol].get(dialect_name, Profile.PROFIDRIVE)


def decode_adr(bus: Bus, adr: int) -> Address:
    """The address an ADR byte of a serial telegram of ``bus`` names (FC or USS)."""
    return decode_fc_adr(adr) if bus is Bus.FC else decode_uss_adr(adr)


def default_dialect(protocol: Bus) -> str:
    """The dialect a drive speaks when none is given: the protocol's own."""
    return DIALECTS_BY_PROTOCOL[protocol][0]


def dialect_fits(protocol: Bus, name: str) -> bool:
    """Whether a drive on a ``protocol`` line can speak the dialect ``name``."""
    return name in DIALECTS_BY_PROTOCOL[protocol]


def pkw_setting(value: object, *, text: bool = False) -> PkwSetting:
    """A master's PKW length: ``auto`` (learned from the drive's answers) or :func:`pkw_words`."""
    if value == AUTO:
        return AUTO
    try:
        return pkw_words(value, text=text)
    except ValueError as exc:
        raise ValueError(str(exc).replace("use 0,", "use auto, 0,")) from None


def pkw_words(value: object, *, text: bool = False) -> int | None:
    """A PKW length: 0, 3 or 4 fixed words; ``variable`` or 127 is None (variable).

    With ``text``, digits as given on a command line (``"4"``, ``"127"``) are
    read as their number. ValueError naming the lengths otherwise.
    """
    if text and isinstance(value, str) and value.isdigit() and len(value) <= 3:
        value = int(value)
    if value == "variable" or (value == VARIABLE_PKW_WORDS and not isinstance(value, bool)):
        return None
    if isinstance(value, int) and not isinstance(value, bool) and value in FIXED_PKW_WORDS:
        return value
    shown = repr(value[:40]) if isinstance(value, str) else repr(value)
    raise ValueError(f"{shown} is not a PKW length: use 0, 3, 4 or variable (127)")
