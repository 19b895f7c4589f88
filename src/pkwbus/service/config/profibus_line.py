"""A PROFIBUS DP line: pkwbus its master (its own station, the slot time, the slaves'
watchdog), its drives DP slaves (:mod:`.profibus`), and what stops a drive on it: its
address against the master's, its parameter channel (the PPO's PKW words, or data record
47 on a DP-V1 slave), and its GSD file against the line's rate and slot time."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar, Final, Literal

from pydantic import Field, StrictInt

from pkwbus.protocol.buses import DP_MAX_ADDRESS, Bus
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.protocol.profibus.gsd import Gsd
from pkwbus.protocol.profidrive.parameters import AXES
from pkwbus.service.config.base import Place, only
from pkwbus.service.config.fields import SlotTime, Watchdog
from pkwbus.service.config.line import LineBase
from pkwbus.service.config.profibus import ProfibusDrive

__all__ = ["MAX_DP_RETRIES", "DpLineSettings", "ProfibusLine", "dp_drive_problems"]

MAX_DP_RETRIES: Final = 8  # a DP slave's request is repeated at most 8 times (DpSlave, SlaveSetup)


class ProfibusLine(LineBase[ProfibusDrive]):
    """A PROFIBUS DP line with pkwbus its master: its characters always 8E1."""

    protocol: Literal[Bus.PROFIBUS]
    refused_keys: ClassVar[Mapping[str, str]] = only(Bus.FC, "fc_address_format")

    # pkwbus's own station, the slot time, the slaves' watchdog.
    master_address: StrictInt = Field(default=2, ge=0, le=DP_MAX_ADDRESS)
    slot_time: SlotTime | None = None
    watchdog: Watchdog | None = None

    def _bus_problems(self) -> list[Place]:
        problems: list[Place] = []
        if self.parity != "E" or self.stopbits != 1:
            problems.append(("parity", "PROFIBUS characters are always 8E1: parity E, stopbits 1"))
        if self.retries > MAX_DP_RETRIES:
            problems.append(("retries", f"at most {MAX_DP_RETRIES} over PROFIBUS"))
        return problems

    def _bus_drive_problems(self, drive: ProfibusDrive) -> list[Place]:
        settings = DpLineSettings(self.master_address, self.baudrate, self.slot_time)
        return dp_drive_problems(settings, drive)


@dataclass(frozen=True, slots=True)
class DpLineSettings:
    """What of its DP line a drive's settings are checked against."""

    master_address: int
    baudrate: int
    slot_time: float | None


def dp_drive_problems(line: DpLineSettings, drive: ProfibusDrive) -> list[Place]:
    """What stops a drive on a DP line: its address, its parameter channel (the PPO's PKW
    words, or data record 47 on a DP-V1 slave), its GSD file against the line. (The
    settings the PPO makes are refused by :class:`~.profibus.ProfibusDrive` itself.)"""
    problems: list[Place] = []
    if drive.address == line.master_address:
        problems.append(
            ("address", f"{drive.address} is the master's own station (master_address)")
        )
    kind = ppo.ppo_type(drive.ppo)
    settings, dp_problems = drive.dp.settings()
    dpv1 = settings is not None and settings.dpv1 is not None
    access = drive.access
    if access is None and (drive.poll or drive.writable):
        problems.append(
            (
                "ppo",
                f"PPO {kind.number} has no PKW words: the drive has no parameter channel"
                " to poll or write (PPO 1, 2 and 5 have one; a DP-V1 slave has data"
                " record 47: dpv1: true)",
            )
        )
    if access == "pkw" and not kind.has_pkw:
        problems.append(("parameter_access", f"pkw: PPO {kind.number} has no PKW words"))
    if access == "ds47":
        if settings is not None and not dpv1:
            problems.append(
                (
                    "parameter_access",
                    "ds47 needs a DP-V1 slave: dpv1: true, or a GSD file with DPV1_Slave = 1",
                )
            )
        elif settings is not None and settings.dpv1 is not None and not settings.dpv1.read_write:
            problems.append(
                (
                    "parameter_access",
                    "ds47: the GSD file says C1_Read_Write_supp = 0: the slave reads and"
                    " writes no data records",
                )
            )
        problems += _text_polls(drive)
        if drive.axis is None and drive.pkw_dialect.name not in AXES:
            problems.append(
                (
                    "parameter_access",
                    f"ds47: the {drive.pkw_dialect.name} dialect documents the PKW channel"
                    " only (give axis to use data record 47 anyway)",
                )
            )
    elif "axis" in drive.model_fields_set:
        problems.append(("axis", "applies to parameter_access: ds47 only"))
    problems += dp_problems
    if settings is not None and settings.gsd is not None:
        problems += _rate_problems(line, settings.gsd)
    return problems


def _rate_problems(line: DpLineSettings, found: Gsd) -> list[Place]:
    """The line's baud rate against the slave's GSD file: a rate it supports, and a slot
    time no shorter than its MaxTsdr at that rate (the latest it may begin to answer)."""
    rate = line.baudrate
    if found.supports(rate) is False:
        return [
            (
                "gsd",
                f"the slave does not run at {rate} baud, the line's rate (its GSD file names"
                f" {found.rates_text()})",
            )
        ]
    tsdr = found.max_tsdr.get(rate)
    slot = line.slot_time
    if slot is not None and tsdr is not None and slot < dp_timing.bits(tsdr, rate):
        return [
            (
                "gsd",
                f"its GSD file's MaxTsdr at {rate} baud, {tsdr} bit times"
                f" ({_ms(dp_timing.bits(tsdr, rate))}), is longer than the line's slot_time"
                f" ({_ms(slot)}): the master would give up on the slave before it may answer",
            )
        ]
    return []


def _text_polls(drive: ProfibusDrive) -> list[Place]:
    """Text parameters do not travel in data record 47 here: their polls are refused."""
    problems: list[Place] = []
    for i, entry in enumerate(drive.poll):
        try:
            spec = drive.spec(entry.ref)
        except ValueError:
            continue  # told where the overrides are checked
        text = entry.type == "text" or (spec is not None and spec.type == "text")
        if text:
            problems.append(
                (f"poll[{i}]", f"{entry.ref} is a text: texts do not travel in data record 47")
            )
    return problems


def _ms(seconds: float) -> str:
    return f"{seconds * 1000:.3g} ms"
