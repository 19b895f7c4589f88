"""A slave's GSD file (the text "device data base" every PROFIBUS vendor publishes), read
as vendors write it: the whole syntax of the PROFIBUS GSD specification (revisions 1
to 5), an unknown keyword ignored, never refused.

What a DP master needs from it: the ident number, the user parameter bytes
with their defaults, the modules with their configuration identifiers, the
baud rates the slave supports and ``MaxTsdr`` at each, and, of a DP-V1 slave,
its class 1 services. Pure: bytes or text in, objects out.

Raises :class:`GsdError` (with the line) for a GSD file that cannot be used,
:class:`~pkwbus.protocol.errors.LocalProtocolError` for a module it lacks.
"""

from __future__ import annotations

from pkwbus.protocol.profibus.gsd.lines import HEADER, GsdError, decode
from pkwbus.protocol.profibus.gsd.model import BAUD_SUFFIXES, FAMILIES, Gsd, GsdModule, SlaveFamily
from pkwbus.protocol.profibus.gsd.ppo_modules import module_for_ppo, ppo_of
from pkwbus.protocol.profibus.gsd.prm import ExtUserPrm
from pkwbus.protocol.profibus.gsd.reader import parse

__all__ = [
    "BAUD_SUFFIXES",
    "FAMILIES",
    "HEADER",
    "ExtUserPrm",
    "Gsd",
    "GsdError",
    "GsdModule",
    "SlaveFamily",
    "decode",
    "module_for_ppo",
    "parse",
    "ppo_of",
]
