"""What a slave on a PROFIBUS DP line is parametrised with: its PPO, ident number, user
parameters, module identifiers and DP-V1 services, as given or read from the drive's
GSD file. One resolver for the configuration file and the command line.

Precedence: what is given (``cfg``, ``user_prm``, ``ident``) over the GSD
file; the GSD file over the PPO's own identifiers. Given identifiers need no
module of the file (the file's module with those identifiers, where it has
one, brings its own parameter bytes). A GSD file is read once for each
content it has (its path, size and modification time), however often its
drive's settings are asked for.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from pkwbus.errors import PkwbusError
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus import gsd
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dp_services
from pkwbus.protocol.profibus.dp.ppo import PpoType
from pkwbus.protocol.profibus.dpv1.msac import Dpv1Setup
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.protocol.profibus.gsd import Gsd, GsdModule

__all__ = [
    "MAX_GSD_BYTES",
    "DpGiven",
    "DpSettings",
    "GsdFileError",
    "Problem",
    "read_gsd_file",
    "resolve",
    "slot_time",
    "watchdog",
]

MAX_GSD_BYTES = 1 << 20
# (what the problem is about: "gsd", "ident", "cfg", "user_prm" or "" for the drive, text)
Problem = tuple[str, str]


class GsdFileError(PkwbusError, ValueError):
    """A GSD file that cannot be read or used; the message names the file."""


@dataclass(frozen=True, slots=True)
class DpSettings:
    """The Set_Prm and Chk_Cfg data of one slave, and the GSD file they came from."""

    ppo: PpoType
    ident: int
    user_prm: bytes
    cfg: bytes
    dpv1: Dpv1Setup | None = None  # a DP-V1 slave, parametrised so (None: DP-V0)
    gsd: Gsd | None = None
    module: GsdModule | None = None  # the file's module these identifiers are


@dataclass(frozen=True, slots=True)
class DpGiven:
    """A slave's DP fields as the user gave them (``gsd`` as a path to open)."""

    ppo: int
    ident: int | None = None
    gsd: str | None = None
    cfg: bytes | None = None
    user_prm: bytes | None = None
    dpv1: bool | None = None  # None: as the GSD file says (else DP-V0)
    gsd_shown: str | None = None  # the path as the user wrote it


def read_gsd_file(path: str, shown: str | None = None) -> Gsd:
    """The GSD file at ``path``; a :class:`GsdFileError` naming it (as ``shown``) and the
    line for one that cannot be read."""
    name = shown or path
    try:
        stat = Path(path).stat()
    except OSError as exc:
        raise GsdFileError(f"cannot read {name}: {exc.strerror or exc}") from None
    return _read(path, name, stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _read(path: str, name: str, size: int, mtime: int) -> Gsd:
    try:
        with Path(path).open("rb") as file:
            data = file.read(MAX_GSD_BYTES + 1)
    except OSError as exc:
        raise GsdFileError(f"cannot read {name}: {exc.strerror or exc}") from None
    if len(data) > MAX_GSD_BYTES:
        raise GsdFileError(f"{name} is larger than 1 MiB: not a GSD file")
    try:
        return gsd.parse(gsd.decode(data))
    except gsd.GsdError as exc:
        raise GsdFileError(f"{name}: {exc}") from None


def resolve(
    given: DpGiven, option: Callable[[str], str] = str
) -> tuple[DpSettings | None, list[Problem]]:
    """The slave's settings, or the problems that stop them; ``option`` names a field as
    the user writes it (``cfg``, or ``--cfg`` on the command line)."""
    kind = ppo.ppo_type(given.ppo)
    problems: list[Problem] = []
    ident, user_prm, cfg = given.ident, b"", kind.cfg
    dpv1 = Dpv1Setup() if given.dpv1 else None
    found: Gsd | None = None
    module: GsdModule | None = None
    if given.gsd is not None:
        shown = given.gsd_shown or given.gsd
        try:
            found = read_gsd_file(given.gsd, shown)
        except GsdFileError as exc:
            problems.append(("gsd", str(exc)))
        else:
            module, more = _from_file(found, shown, kind, given, option)
            problems += more
            if found.dpv1 is not None and given.dpv1 is not False:
                dpv1 = found.dpv1  # the GSD's C1_Max_Data_Len and C1_Response_Timeout
            if ident is not None and ident != found.ident:
                problems.append(
                    (
                        "ident",
                        f"0x{ident:04X} contradicts the GSD file's Ident_Number"
                        f" 0x{found.ident:04X}",
                    )
                )
            ident = found.ident
            if module is not None:
                cfg = module.cfg
            try:
                user_prm = found.prm_for([module] if module is not None else [])
            except LocalProtocolError as exc:
                problems.append(("gsd", f"{shown}: {exc}"))
    elif ident is None:
        problems.append(
            (
                "",
                f"give the slave's ident number ({option('ident')} 0x0402) or its GSD file"
                f" ({option('gsd')} PATH)",
            )
        )
    if given.cfg is not None:
        cfg = given.cfg
    if given.user_prm is not None:
        user_prm = given.user_prm
    problems += _cfg_problems(cfg, kind)
    if problems or ident is None:
        return None, problems
    try:
        dp_services.Parameters(ident, user_prm=user_prm).encode()
    except LocalProtocolError as exc:
        return None, [("user_prm", str(exc))]
    return DpSettings(kind, ident, user_prm, cfg, dpv1, found, module), []


def _from_file(
    found: Gsd, shown: str, kind: PpoType, given: DpGiven, option: Callable[[str], str]
) -> tuple[GsdModule | None, list[Problem]]:
    """The file's module for the slave: the one with the given identifiers (none needed),
    else the PPO's; and what stops the file from being used."""
    if found.station_type != 0:
        return None, [
            ("gsd", f"{shown} describes a DP master (Station_Type {found.station_type}), not a"
             " slave"),
        ]  # fmt: skip
    if given.cfg is not None:
        return next((m for m in found.modules if m.cfg == given.cfg), None), []
    module = gsd.module_for_ppo(found, kind)
    if module is None:
        known = ", ".join(repr(m.name) for m in found.modules) or "none"
        return None, [
            (
                "gsd",
                f"{shown} has no module for PPO {kind.number} (modules: {known}); give"
                f" {option('cfg')}",
            )
        ]
    return module, []


def _cfg_problems(cfg: bytes, kind: PpoType) -> list[Problem]:
    try:
        dp_services.check_cfg(cfg)
        lengths = dp_services.io_lengths(cfg)
    except LocalProtocolError as exc:
        return [("cfg", str(exc))]
    if lengths != (kind.length, kind.length):
        return [
            (
                "cfg",
                f"{cfg.hex(' ').upper()} sets up {lengths[0]}/{lengths[1]} bytes in/out;"
                f" PPO {kind.number} has {kind.length}",
            )
        ]
    return []


def slot_time(baudrate: int, given: float | None, gsds: Iterable[Gsd | None]) -> float:
    """A line's slot time: as ``given``, else the default at ``baudrate`` waiting for the
    slowest of its slaves (the longest ``MaxTsdr_<rate>`` of their GSD files: a slave may
    begin to answer that many bit times after a request). The one rule of the service's
    lines and the commands' (which address one slave)."""
    if given is not None:
        return float(given)
    tsdrs = [g.max_tsdr[baudrate] for g in gsds if g is not None and baudrate in g.max_tsdr]
    return dp_timing.default_slot_time(baudrate, max(tsdrs, default=None))


def watchdog(slot: float, retries: int, slaves: int, given: float | None = None) -> float:
    """The watchdog time a line's slaves are parametrised with: as ``given``, else ten
    worst-case cycles of the master, at least a second.

    A slave whose watchdog is on leaves data exchange (its outputs to their safe state)
    when no frame of its master reached it within the watchdog time (IEC 61158 / EN 50170
    DP, Set_Prm watchdog factors). The master addresses each slave of its cycle once a
    cycle, and each exchange may take its retries, each up to a slot time: a cycle is
    ``slaves`` such exchanges, so the time grows with the slaves the master cycles
    through (the service: every slave of the line; a command: the one it addresses)."""
    if given:
        return float(given)
    return max(1.0, 10 * slot * (retries + 1) * slaves)
