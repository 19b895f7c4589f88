"""What a drive on a PROFIBUS DP line needs to be parametrised: its PPO, ident number,
user parameters and module identifiers, given in the configuration or read from the
drive's GSD file (PROFIBUS DP GSD specification; the drive's PROFIBUS manual names
where the vendor publishes it)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from pkwbus import dp_settings
from pkwbus.dp_settings import DpGiven, DpSettings
from pkwbus.problems import short
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.protocol.profibus.gsd import Gsd
from pkwbus.protocol.profidrive.parameters import AXES
from pkwbus.service.config.base import Place

if TYPE_CHECKING:
    from pkwbus.service.config.drive import Drive
    from pkwbus.service.config.line import Line

__all__ = [
    "DpDrive",
    "DpSettings",
    "dp_drive_problems",
    "hex_bytes",
    "ident_number",
    "resolve_gsd_path",
]


@dataclass(frozen=True, slots=True)
class DpDrive:
    """The DP fields of a drive as configured (``gsd`` already made absolute)."""

    ppo: int
    ident: int | None
    gsd: str | None
    gsd_given: str | None
    cfg: bytes | None
    user_prm: bytes | None
    dpv1: bool | None = None  # as configured; None: as the GSD file says (else DP-V0)

    def settings(self) -> tuple[DpSettings | None, list[Place]]:
        """The slave's settings, or the problems (each with its place) that stop them
        (:func:`pkwbus.dp_settings.resolve`, as the command line's)."""
        given = DpGiven(
            self.ppo, self.ident, self.gsd, self.cfg, self.user_prm, self.dpv1, self.gsd_given
        )
        return dp_settings.resolve(given)


def ident_number(value: object) -> int:
    """An ident number: 0x0402 in YAML is already a number; "0x0402" as text too."""
    if isinstance(value, str):
        try:
            value = int(value.strip(), 0)
        except ValueError:
            raise ValueError(f"{short(value)} is not a 16-bit number such as 0x0402") from None
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
        raise ValueError(f"{short(value)} is not a 16-bit number such as 0x0402")
    return value


def hex_bytes(value: object) -> bytes:
    """Bytes written as hex text ("F3 F1", "0xF3,0xF1") or a list of numbers 0-255."""
    if isinstance(value, list):
        if all(isinstance(b, int) and not isinstance(b, bool) and 0 <= b <= 255 for b in value):
            return bytes(value)
        raise ValueError("must be numbers 0-255, such as [0xF3, 0xF1]")
    if not isinstance(value, str):
        raise ValueError(f'{short(value)} is not hex bytes such as "F3 F1"')
    cleaned = value.replace(",", " ").replace("0x", "").replace("0X", "")
    try:
        return bytes.fromhex(cleaned)
    except ValueError:
        raise ValueError(f'{short(value)} is not hex bytes such as "F3 F1"') from None


def resolve_gsd_path(value: str, base: Path | None) -> str:
    """A GSD path relative to the configuration file's folder, made absolute."""
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    return str(path)


def dp_drive_problems(line: Line, drive: Drive) -> list[Place]:
    """What stops a drive on a DP line: its address, the settings the PPO makes, its
    parameter channel (the PPO's PKW words, or data record 47 on a DP-V1 slave)."""
    problems: list[Place] = []
    if drive.address == line.master_address:
        problems.append(
            ("address", f"{drive.address} is the master's own station (master_address)")
        )
    problems += [
        (key, "the PPO sets it over PROFIBUS: give ppo")
        for key in ("pkw_words", "pzd_words", "ind_layout")
        if key in drive.model_fields_set
    ]
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


def _rate_problems(line: Line, found: Gsd) -> list[Place]:
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


def _text_polls(drive: Drive) -> list[Place]:
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
