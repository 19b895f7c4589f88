"""Why a DP slave is not in data exchange, in the words of its diagnosis: it refuses its
parameters or its configuration (PROFIBUS DP Slave_Diag, station status 1: Prm_Fault,
Cfg_Fault), or another master owns it (Slave_Diag, byte 4: Diag.Master_Add).

The command line and the service word it alike; each names its own settings: the
command's options, or the keys of the drive's configuration.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass

from pkwbus.master.wires.profibus.cycle import SlaveLocked

__all__ = ["CONFIGURATION", "OPTIONS", "Settings", "refusal", "why_not_exchanging"]


@dataclass(frozen=True, slots=True)
class Settings:
    """The names of the settings Set_Prm and Chk_Cfg carry: the ident number, the
    parameters as a whole, the configuration (the modules)."""

    ident: str
    parameters: str
    configuration: str


OPTIONS = Settings("--ident, --gsd", "--ident, --gsd, --user-prm", "--ppo, --cfg, --gsd")
CONFIGURATION = Settings("ident, gsd", "ident, gsd, user_prm", "ppo, cfg, gsd")


def refusal(
    address: int,
    flags: Collection[str],
    ident: int | None,
    sent: int | None,
    settings: Settings,
) -> str | None:
    """Why slave ``address`` refuses what it was sent, where its diagnosis (``flags``, the
    ``ident`` number it reports) says it does; ``sent`` the ident number it was
    parametrised with (None: not known here). None where the diagnosis names no fault."""
    if "prm_fault" in flags:
        if ident is not None and sent is not None and ident != sent:
            why = f"its ident number is {ident:#06x}, not {sent:#06x} ({settings.ident})"
        else:
            why = f"its ident number or user parameters ({settings.parameters})"
        return f"slave {address} refuses its parameters (Prm_Fault): {why}"
    if "cfg_fault" in flags:
        return (
            f"slave {address} refuses its configuration (Cfg_Fault): its modules are not"
            f" those sent ({settings.configuration})"
        )
    return None


def why_not_exchanging(
    address: int,
    locked: bool,
    owner: int | None,
    flags: Collection[str],
    ident: int | None,
    sent: int | None,
    settings: Settings,
) -> str | None:
    """Why slave ``address`` is not in data exchange, where its state (``locked``: owned by
    another master) or its latest diagnosis says (None: neither says)."""
    if locked:
        return str(SlaveLocked(address, owner))
    return refusal(address, flags, ident, sent, settings)
