"""What a drive on a PROFIBUS DP line needs to be parametrised: its PPO, ident number,
user parameters and module identifiers, given in the configuration or read from the
drive's GSD file (PROFIBUS DP GSD specification; the drive's PROFIBUS manual names
where the vendor publishes it)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pkwbus import dp_settings
from pkwbus.dp_settings import DpGiven, DpSettings
from pkwbus.problems import short
from pkwbus.service.config.base import Place

__all__ = [
    "DpDrive",
    "DpSettings",
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
