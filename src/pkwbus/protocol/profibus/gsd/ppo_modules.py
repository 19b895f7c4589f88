"""Which of a drive's GSD modules is which PPO type.

A module is PPO *n* when its configuration identifiers are the PPO's (an
empty slot ``0x00`` before them aside: Siemens MICROMASTER 4 writes PPO 3 as
``0x00, 0xF1``), else when its name says "PPO *n*" (the lengths its
identifiers set up are checked where it is used).
"""

from __future__ import annotations

import re

from pkwbus.protocol.profibus.dp.ppo import PPO_TYPES, PpoType
from pkwbus.protocol.profibus.gsd.model import Gsd, GsdModule

__all__ = ["module_for_ppo", "ppo_of"]

_NAMED = re.compile(r"ppo\s*(\d+)", re.IGNORECASE)


def ppo_of(module: GsdModule) -> int | None:
    """The PPO type the module is, None where it is none (a standard telegram, say)."""
    cfg = module.cfg.lstrip(b"\x00")
    for number, kind in PPO_TYPES.items():
        if cfg == kind.cfg:
            return number
    named = _NAMED.search(module.name)
    if named is not None and int(named.group(1)) in PPO_TYPES:
        return int(named.group(1))
    return None


def module_for_ppo(found: Gsd, kind: PpoType) -> GsdModule | None:
    """The file's module for PPO ``kind``: one whose identifiers are the PPO's first, else
    one named so; None where the file has none."""
    exact = [m for m in found.modules if m.cfg.lstrip(b"\x00") == kind.cfg]
    if exact:
        return exact[0]
    return next((m for m in found.modules if ppo_of(m) == kind.number), None)
