"""PROFIBUS DP-V0 services: Slave_Diag, Set_Prm, Chk_Cfg, Get_Cfg, Global_Control, Data_Exchange.

The request frames a master sends and the answers it decodes (EN 50170
vol. 2 part 3, "DP services"; VIPA IM 353 manual, "diagnosis" for the
diagnosis bytes; Balluff BNI PBS manual for Set_Prm; Beckhoff FC310x manual
for configuration identifiers). Pure: bytes in, objects out.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for a request that cannot be
built and :class:`~pkwbus.protocol.errors.RemoteProtocolError` for received data that
does not decode.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus.fdl import BROADCAST, DataFrame, Function, request_fc

__all__ = [
    "DIAG_FLAGS",
    "MASTER_SAP",
    "MAX_USER_PRM",
    "NO_MASTER",
    "WATCHDOG_TICK",
    "ControlCommand",
    "Diagnosis",
    "Direction",
    "Module",
    "Parameters",
    "Service",
    "check_cfg",
    "decode_diagnosis",
    "decode_parameters",
    "encode_diagnosis",
    "global_control_clear",
    "io_lengths",
    "parse_cfg",
    "request",
    "watchdog_factors",
]

MASTER_SAP: Final = 62
NO_MASTER: Final = 0xFF
WATCHDOG_TICK: Final = 0.01  # seconds per unit of WD factor 1 x WD factor 2
MAX_USER_PRM: Final = 237  # 244 bytes of Set_Prm data minus the 7 fixed bytes


class Service(enum.IntEnum):
    """The destination SAP of each service (Data_Exchange has none)."""

    GLOBAL_CONTROL = 58
    GET_CFG = 59
    SLAVE_DIAG = 60
    SET_PRM = 61
    CHK_CFG = 62


def request(
    service: Service | None,
    slave: int,
    master: int,
    data: bytes = b"",
    *,
    fcb: bool,
    fcv: bool,
) -> DataFrame:
    """The SRD request of ``service`` (None: Data_Exchange) to ``slave``."""
    if not 0 <= slave <= 125:
        raise LocalProtocolError(f"slave address {slave} is outside 0-125")
    if not 0 <= master <= 125:
        raise LocalProtocolError(f"master address {master} is outside 0-125")
    fc = request_fc(Function.SRD_HIGH, fcb=fcb, fcv=fcv)
    if service is None:
        return DataFrame(slave, master, fc, data=data)
    return DataFrame(slave, master, fc, int(service), MASTER_SAP, data)


# ---------------------------------------------------------------- Slave_Diag

# Byte 1, byte 2, byte 3 flags, by bit (VIPA IM 353, "slave diagnosis").
_STATION_1 = {
    0: "station_non_existent",
    1: "not_ready",
    2: "cfg_fault",
    3: "ext_diag",
    4: "not_supported",
    5: "invalid_response",
    6: "prm_fault",
    7: "master_lock",
}
_STATION_2 = {
    0: "prm_required",
    1: "stat_diag",
    3: "watchdog_on",
    4: "freeze_mode",
    5: "sync_mode",
    7: "deactivated",
}
_STATION_3 = {7: "ext_diag_overflow"}
DIAG_FLAGS: Final = (*_STATION_1.values(), *_STATION_2.values(), *_STATION_3.values())


@dataclass(frozen=True, slots=True)
class Diagnosis:
    """A decoded Slave_Diag answer: named flags, the owning master, the ident number."""

    flags: frozenset[str]
    master: int | None  # None: no master owns the slave (0xFF)
    ident: int
    extended: bytes = b""

    def has(self, flag: str) -> bool:
        if flag not in DIAG_FLAGS:
            raise LocalProtocolError(f"no diagnosis flag named {flag!r}")
        return flag in self.flags

    @property
    def ready(self) -> bool:
        """Ready for data exchange: parametrised, configured, no fault."""
        return not self.flags & {"prm_required", "not_ready", "cfg_fault", "prm_fault"}

    def owned_by_other(self, master: int) -> bool:
        """Whether the diagnosis names a master other than ``master`` as the owner."""
        return self.master is not None and self.master != master


def decode_diagnosis(data: bytes) -> Diagnosis:
    if len(data) < 6:
        raise RemoteProtocolError(f"diagnosis of {len(data)} bytes (at least 6)")
    flags = {name for bit, name in _STATION_1.items() if data[0] >> bit & 1}
    flags |= {name for bit, name in _STATION_2.items() if data[1] >> bit & 1}
    flags |= {name for bit, name in _STATION_3.items() if data[2] >> bit & 1}
    master = None if data[3] == NO_MASTER else data[3]
    return Diagnosis(frozenset(flags), master, data[4] << 8 | data[5], bytes(data[6:]))


def encode_diagnosis(diag: Diagnosis) -> bytes:
    """The answer bytes of a diagnosis (the slave's side; byte 2 bit 2 is always 1)."""
    unknown = diag.flags - set(DIAG_FLAGS)
    if unknown:
        raise LocalProtocolError(f"no diagnosis flag named {sorted(unknown)[0]!r}")
    if diag.master is not None and not 0 <= diag.master <= 125:
        raise LocalProtocolError(f"master address {diag.master} is outside 0-125")
    _check_ident(diag.ident)

    def byte(table: dict[int, str]) -> int:
        return sum(1 << bit for bit, name in table.items() if name in diag.flags)

    owner = NO_MASTER if diag.master is None else diag.master
    head = bytes((byte(_STATION_1), byte(_STATION_2) | 0x04, byte(_STATION_3), owner))
    return head + diag.ident.to_bytes(2, "big") + diag.extended


def _check_ident(ident: int) -> None:
    if not 0 <= ident <= 0xFFFF:
        raise LocalProtocolError(f"ident number {ident} is not 16 bits")


# ------------------------------------------------------------------ Set_Prm

_WD_ON = 0x08
_FREEZE = 0x10
_SYNC = 0x20
_UNLOCK = 0x40
_LOCK = 0x80


def watchdog_factors(seconds: float) -> tuple[int, int]:
    """WD factor 1 and 2 for a watchdog of at least ``seconds`` (10 ms x f1 x f2)."""
    ticks = math.ceil(round(seconds / WATCHDOG_TICK, 6))
    if not 1 <= ticks <= 255 * 255:
        raise LocalProtocolError(
            f"watchdog of {seconds} s is outside {WATCHDOG_TICK} s - {255 * 255 * WATCHDOG_TICK} s"
        )
    f2 = math.ceil(ticks / 255)
    return math.ceil(ticks / f2), f2


@dataclass(frozen=True, slots=True)
class Parameters:
    """The Set_Prm data: station status, watchdog, min TSDR, ident, group, user parameters."""

    ident: int
    watchdog: tuple[int, int] | None = None  # (WD factor 1, WD factor 2); None: watchdog off
    min_tsdr: int = 0  # bit times; 0 keeps the slave's value
    group: int = 0
    user_prm: bytes = b""
    lock: bool = True
    unlock: bool = False
    sync: bool = False
    freeze: bool = False

    @property
    def watchdog_seconds(self) -> float | None:
        if self.watchdog is None:
            return None
        return WATCHDOG_TICK * self.watchdog[0] * self.watchdog[1]

    def encode(self) -> bytes:
        _check_ident(self.ident)
        f1, f2 = self.watchdog or (1, 1)
        if not (1 <= f1 <= 255 and 1 <= f2 <= 255):
            raise LocalProtocolError(f"watchdog factors {f1}, {f2} are outside 1-255")
        if not 0 <= self.min_tsdr <= 255:
            raise LocalProtocolError(f"min TSDR {self.min_tsdr} is outside 0-255 bit times")
        if not 0 <= self.group <= 255:
            raise LocalProtocolError(f"group {self.group} is not a byte")
        if len(self.user_prm) > MAX_USER_PRM:
            raise LocalProtocolError(f"{len(self.user_prm)} user parameter bytes (at most 237)")
        status = (
            (_WD_ON if self.watchdog is not None else 0)
            | (_FREEZE if self.freeze else 0)
            | (_SYNC if self.sync else 0)
            | (_UNLOCK if self.unlock else 0)
            | (_LOCK if self.lock else 0)
        )
        fixed = bytes((status, f1, f2, self.min_tsdr)) + self.ident.to_bytes(2, "big")
        return fixed + bytes((self.group,)) + self.user_prm


def decode_parameters(data: bytes) -> Parameters:
    """Set_Prm data as a slave receives it."""
    if len(data) < 7:
        raise RemoteProtocolError(f"Set_Prm of {len(data)} bytes (at least 7)")
    status = data[0]
    watchdog = (data[1], data[2]) if status & _WD_ON else None
    if watchdog is not None and 0 in watchdog:
        raise RemoteProtocolError("Set_Prm with a watchdog factor of 0")
    return Parameters(
        ident=data[4] << 8 | data[5],
        watchdog=watchdog,
        min_tsdr=data[3],
        group=data[6],
        user_prm=bytes(data[7:]),
        lock=bool(status & _LOCK),
        unlock=bool(status & _UNLOCK),
        sync=bool(status & _SYNC),
        freeze=bool(status & _FREEZE),
    )


# ----------------------------------------------------- configuration identifiers


class Direction(enum.IntEnum):
    NONE = 0
    INPUT = 1
    OUTPUT = 2
    BOTH = 3


@dataclass(frozen=True, slots=True)
class Module:
    """One configuration identifier (with its length and manufacturer bytes)."""

    raw: bytes
    inputs: int  # bytes
    outputs: int  # bytes
    consistent: bool

    @property
    def empty(self) -> bool:
        return self.raw == b"\x00"


def _length_byte(byte: int) -> tuple[int, bool]:
    """Bytes and consistency of a special format length byte."""
    units = (byte & 0x3F) + 1
    return units * (2 if byte & 0x40 else 1), bool(byte & 0x80)


def parse_cfg(data: bytes) -> tuple[Module, ...]:
    """Split configuration identifiers into modules (normal and special format, empty slots)."""
    modules: list[Module] = []
    pos = 0
    while pos < len(data):
        start = pos
        head = data[pos]
        pos += 1
        direction = head >> 4 & 0x03
        if direction:  # normal format: bits 0-3 length - 1, bit 6 words, bit 7 consistent
            size = ((head & 0x0F) + 1) * (2 if head & 0x40 else 1)
            inputs = size if direction & 1 else 0
            outputs = size if direction & 2 else 0
            modules.append(Module(bytes((head,)), inputs, outputs, bool(head & 0x80)))
            continue
        # Special format: bits 6-7 say which length bytes follow (outputs first),
        # bits 0-3 how many manufacturer bytes follow them; 00 is an empty slot.
        kind = head >> 6
        extra = head & 0x0F
        if extra == 0x0F:
            raise RemoteProtocolError(f"configuration byte {head:#04x} is reserved")
        count = {0: 0, 1: 1, 2: 1, 3: 2}[kind]
        if pos + count + extra > len(data):
            raise RemoteProtocolError(
                f"configuration identifier {head:#04x} at byte {start} is cut short"
            )
        lengths = [_length_byte(b) for b in data[pos : pos + count]]
        pos += count + extra
        outputs = inputs = 0
        consistent = all(c for _, c in lengths) and bool(lengths)
        if kind == 1:
            inputs = lengths[0][0]
        elif kind == 2:
            outputs = lengths[0][0]
        elif kind == 3:
            outputs, inputs = lengths[0][0], lengths[1][0]
        modules.append(Module(bytes(data[start:pos]), inputs, outputs, consistent))
    return tuple(modules)


def io_lengths(cfg: bytes) -> tuple[int, int]:
    """(input bytes, output bytes) that a configuration sets up."""
    modules = parse_cfg(cfg)
    return sum(m.inputs for m in modules), sum(m.outputs for m in modules)


def check_cfg(cfg: bytes) -> None:
    """A clear local error for configuration bytes a master must not send."""
    if not cfg:
        raise LocalProtocolError("an empty configuration")
    try:
        inputs, outputs = io_lengths(cfg)
    except RemoteProtocolError as exc:
        raise LocalProtocolError(str(exc)) from None
    if inputs > 244 or outputs > 244:
        raise LocalProtocolError(f"configuration of {inputs} input, {outputs} output bytes")


# ------------------------------------------------------------- Global_Control


class ControlCommand(enum.IntFlag):
    CLEAR_DATA = 0x02
    UNFREEZE = 0x04
    FREEZE = 0x08
    UNSYNC = 0x10
    SYNC = 0x20


def global_control_clear(master: int, group: int = 0) -> DataFrame:
    """Global_Control Clear to every slave (SDN broadcast): the only command pkwbus sends."""
    if not 0 <= master <= 125:
        raise LocalProtocolError(f"master address {master} is outside 0-125")
    if not 0 <= group <= 255:
        raise LocalProtocolError(f"group select {group} is not a byte")
    data = bytes((int(ControlCommand.CLEAR_DATA), group))
    fc = request_fc(Function.SDN_HIGH)
    return DataFrame(BROADCAST, master, fc, int(Service.GLOBAL_CONTROL), MASTER_SAP, data)
