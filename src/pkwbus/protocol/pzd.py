"""Process data: control and status words with named bits, REF/MAV scaling.

A monitoring master must never take control of a drive: both the FC profile
and PROFIdrive ignore the control word while its bit 10 is 0 ("data not
valid" / "no control by PLC"), so :data:`MONITORING_CTW` is 0.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for a bit name, word or
percentage out of range.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from types import MappingProxyType
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError

__all__ = [
    "CONTROL_BITS",
    "CTW_BIT_DATA_VALID",
    "FC_CONTROL_BITS",
    "FC_STATUS_BITS",
    "MONITORING_CTW",
    "PROFIDRIVE_CONTROL_BITS",
    "PROFIDRIVE_STATUS_BITS",
    "REF_100_PERCENT",
    "STATUS_BITS",
    "Profile",
    "control_word",
    "percent_to_ref",
    "ref_to_percent",
    "status_bits",
    "status_word",
    "takes_control",
]

CTW_BIT_DATA_VALID: Final = 10
MONITORING_CTW: Final = 0x0000
REF_100_PERCENT: Final = 0x4000


class Profile(enum.StrEnum):
    FC = "fc"
    PROFIDRIVE = "profidrive"


def _bits(names: dict[int, str]) -> Mapping[int, str]:
    return MappingProxyType(names)


FC_CONTROL_BITS = _bits(
    {
        0: "reference_value_lsb",
        1: "reference_value_msb",
        2: "dc_brake",
        3: "coasting",
        4: "quick_stop",
        5: "hold_output_frequency",
        6: "ramp_stop",
        7: "reset",
        8: "jog",
        9: "ramp_2",
        10: "data_valid",
        11: "relay_01",
        12: "relay_02",
        13: "setup_lsb",
        14: "setup_msb",
        15: "reverse",
    }
)
FC_STATUS_BITS = _bits(
    {
        0: "control_ready",
        1: "drive_ready",
        2: "enabled",
        3: "trip",
        4: "error",
        6: "trip_lock",
        7: "warning",
        8: "at_reference",
        9: "bus_control",
        10: "frequency_within_limit",
        11: "running",
        12: "stopped_autostart",
        13: "voltage_exceeded",
        14: "torque_exceeded",
        15: "timer_exceeded",
    }
)
PROFIDRIVE_CONTROL_BITS = _bits(
    {
        0: "on",
        1: "no_coast_stop",
        2: "no_quick_stop",
        3: "enable_operation",
        4: "enable_ramp_generator",
        5: "continue_ramp_generator",
        6: "enable_setpoint",
        7: "fault_acknowledge",
        8: "jog_1",
        9: "jog_2",
        10: "control_by_plc",
        11: "setpoint_inversion",
        13: "motorized_potentiometer_up",
        14: "motorized_potentiometer_down",
    }
)
PROFIDRIVE_STATUS_BITS = _bits(
    {
        0: "ready_to_switch_on",
        1: "ready",
        2: "operation_enabled",
        3: "fault",
        4: "no_coast_stop",
        5: "no_quick_stop",
        6: "switching_on_inhibited",
        7: "warning",
        8: "speed_within_tolerance",
        9: "control_requested",
        10: "reference_reached",
        11: "limit_reached",
    }
)

STATUS_BITS: Mapping[Profile, Mapping[int, str]] = MappingProxyType(
    {Profile.FC: FC_STATUS_BITS, Profile.PROFIDRIVE: PROFIDRIVE_STATUS_BITS}
)
CONTROL_BITS: Mapping[Profile, Mapping[int, str]] = MappingProxyType(
    {Profile.FC: FC_CONTROL_BITS, Profile.PROFIDRIVE: PROFIDRIVE_CONTROL_BITS}
)


def status_bits(word: int, profile: Profile) -> dict[str, bool]:
    """Every named bit of a status word, by name."""
    return {name: bool(word >> bit & 1) for bit, name in STATUS_BITS[profile].items()}


def status_word(profile: Profile, **bits: bool) -> int:
    """Build a status word from named bits (the simulator's side)."""
    return _word(STATUS_BITS[profile], bits)


def control_word(profile: Profile, **bits: bool) -> int:
    """Build a control word from named bits; bit 10 stays 0 unless named."""
    return _word(CONTROL_BITS[profile], bits)


def _word(table: Mapping[int, str], bits: Mapping[str, bool]) -> int:
    by_name = {name: bit for bit, name in table.items()}
    word = 0
    for name, on in bits.items():
        if name not in by_name:
            raise LocalProtocolError(f"no bit named {name!r}")
        if on:
            word |= 1 << by_name[name]
    return word


def takes_control(ctw: int) -> bool:
    """Whether a control word would be acted on by the drive (bit 10 set)."""
    return bool(ctw >> CTW_BIT_DATA_VALID & 1)


def ref_to_percent(raw: int) -> float:
    """A REF or MAV word as percent: 0x4000 = 100 %, two's complement below 0."""
    if not 0 <= raw <= 0xFFFF:
        raise LocalProtocolError(f"{raw} is not a 16-bit word")
    signed = raw - 0x10000 if raw & 0x8000 else raw
    return signed * 100.0 / REF_100_PERCENT


def percent_to_ref(percent: float) -> int:
    """Percent as a REF word (rounded to the nearest step)."""
    signed = round(percent * REF_100_PERCENT / 100.0)
    if not -0x8000 <= signed <= 0x7FFF:
        raise LocalProtocolError(f"{percent} % is outside the REF range")
    return signed & 0xFFFF
