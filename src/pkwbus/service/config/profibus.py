"""A drive on a PROFIBUS DP line, and what it needs to be parametrised: its PPO, ident
number, user parameters and module identifiers, given in the configuration or read from
the drive's GSD file (PROFIBUS DP GSD specification; the drive's PROFIBUS manual names
where the vendor publishes it)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, ClassVar, Literal, TypeVar

from pydantic import (
    Field,
    PlainValidator,
    StrictBool,
    StrictInt,
    ValidationInfo,
    field_validator,
)

from pkwbus.catalog import dp_settings
from pkwbus.catalog.dp_settings import DpGiven, DpSettings
from pkwbus.notation.problems import short
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.dialects import IndLayout
from pkwbus.protocol.profibus.dp.ppo import LAYOUT as PPO_LAYOUT
from pkwbus.protocol.profibus.dp.ppo import ppo_type
from pkwbus.protocol.serial.telegram import BlockShape
from pkwbus.service.config.base import Place
from pkwbus.service.config.drive import DriveBase

__all__ = [
    "DpDrive",
    "DpSettings",
    "ProfibusDrive",
    "hex_bytes",
    "ident_number",
    "resolve_gsd_path",
]

T = TypeVar("T")


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
        (:func:`pkwbus.catalog.dp_settings.resolve`, as the command line's)."""
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


def _optional(check: Callable[[object], T]) -> Callable[[object], T | None]:
    return lambda value: None if value is None else check(value)


_BY_PPO = "the PPO sets it over PROFIBUS: give ppo"


class ProfibusDrive(DriveBase):
    """A slave on a PROFIBUS DP line: its PPO, and the ident number or the GSD file
    (+ cfg, user_prm); its parameters through the PPO's PKW words or data record 47."""

    protocol: ClassVar[Literal[Bus.PROFIBUS]] = Bus.PROFIBUS
    refused_keys: ClassVar[Mapping[str, str]] = {
        **DriveBase.refused_keys,
        **dict.fromkeys(("pkw_words", "pzd_words", "ind_layout"), _BY_PPO),
    }

    ppo: StrictInt = Field(default=1, ge=1, le=5)
    ident: Annotated[int | None, PlainValidator(_optional(ident_number))] = None
    gsd: str | None = Field(default=None, strict=True)
    cfg: Annotated[bytes | None, PlainValidator(_optional(hex_bytes))] = None
    user_prm: Annotated[bytes | None, PlainValidator(_optional(hex_bytes))] = None
    # DP-V1: None follows the GSD file (DPV1_Slave); parameters through the PPO's PKW words
    # or PROFIdrive data record 47 (None: PKW where the PPO has it, else data record 47 on a
    # DP-V1 slave); the drive object (axis) of data record 47 (None: the dialect's).
    dpv1: StrictBool | None = None
    parameter_access: Literal["pkw", "ds47"] | None = None
    axis: StrictInt | None = Field(default=None, ge=0, le=255)

    @field_validator("gsd")
    @classmethod
    def _gsd_path(cls, value: str | None, info: ValidationInfo) -> str | None:
        """Relative to the configuration file's folder."""
        if value is None:
            return None
        if not value.strip() or any(ord(c) < 0x20 for c in value):
            raise ValueError("must be the path of the drive's GSD file")
        context = info.context if isinstance(info.context, dict) else {}
        base = context.get("base")
        return resolve_gsd_path(value, base if isinstance(base, Path) else None)

    @property
    def layout(self) -> IndLayout:
        """In a PPO always PROFIdrive's."""
        return PPO_LAYOUT

    @property
    def shape(self) -> BlockShape:
        """The PPO's."""
        kind = ppo_type(self.ppo)
        return BlockShape(kind.pkw_words, kind.pzd_words)

    @property
    def sim_shape(self) -> tuple[object, ...]:
        """One PPO (each simulated slave has its own dialect and ident)."""
        return (self.ppo, self.cfg)

    @property
    def dp(self) -> DpDrive:
        """The PROFIBUS DP fields, as given."""
        return DpDrive(self.ppo, self.ident, self.gsd, None, self.cfg, self.user_prm, self.dpv1)

    @property
    def access(self) -> Literal["pkw", "ds47"] | None:
        """How its parameters are reached: as configured, else through the PPO's PKW words
        where it has them, else data record 47 on a DP-V1 slave; None: no way (a PPO
        without PKW on a DP-V0 slave)."""
        if self.parameter_access is not None:
            return self.parameter_access
        if ppo_type(self.ppo).has_pkw:
            return "pkw"
        settings = self.dp.settings()[0]
        dpv1 = settings.dpv1 if settings is not None else None
        return "ds47" if dpv1 is not None and dpv1.read_write else None
