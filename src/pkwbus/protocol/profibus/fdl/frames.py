"""PROFIBUS FDL (layer 2) frames: SD1, SD2, SD3, SD4 and SC, encoded and decoded.

Frame formats (EN 50170 vol. 2 part 4, "telegram formats"; Felser PROFIBUS
manual, "telegram structure"):

- SD1 ``10 DA SA FC FCS 16``: no data;
- SD2 ``68 LE LEr 68 DA SA FC [DSAP] [SSAP] data FCS 16``: LE = LEr counts DA
  up to the last data byte (4-249);
- SD3 ``A2 DA SA FC data(8) FCS 16``: exactly 8 bytes after FC (the encoder
  uses it for 8 data bytes without SAPs; with SAPs it writes SD2, as slaves do);
- SD4 ``DC DA SA``: the token;
- SC ``E5``: short acknowledge.

FCS is the sum of DA up to the last data byte, modulo 256. Bit 7 of DA (SA)
set means a DSAP (SSAP) byte follows FC, DSAP first. Pure: bytes in, objects out.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` from :func:`encode`
for a frame FDL cannot carry, and :class:`~pkwbus.protocol.errors.RemoteProtocolError`
from :func:`decode_body` for a frame body FDL does not allow.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError

__all__ = [
    "BROADCAST",
    "ED",
    "MAX_ADDRESS",
    "MAX_FRAME",
    "MAX_LE",
    "MAX_SAP",
    "MIN_LE",
    "SC",
    "SD1",
    "SD2",
    "SD3",
    "SD3_DATA",
    "SD4",
    "DataFrame",
    "Frame",
    "FrameControl",
    "Function",
    "ShortAck",
    "StationType",
    "Status",
    "Token",
    "decode_body",
    "encode",
    "fcs",
    "request_fc",
    "response_fc",
]

SD1: Final = 0x10
SD2: Final = 0x68
SD3: Final = 0xA2
SD4: Final = 0xDC
SC: Final = 0xE5
ED: Final = 0x16

BROADCAST: Final = 127
MAX_ADDRESS: Final = 126
MAX_SAP: Final = 63
MIN_LE: Final = 4
MAX_LE: Final = 249
SD3_DATA: Final = 8
MAX_FRAME: Final = MAX_LE + 6  # 68 LE LEr 68 + LE bytes + FCS 16

_EXT: Final = 0x80
_FC_REQUEST: Final = 0x40
_FC_FCB: Final = 0x20
_FC_FCV: Final = 0x10


class Function(enum.IntEnum):
    """Request functions, FC bits 0-3 with bit 6 set."""

    TIME_EVENT = 0
    SDA_LOW = 3
    SDN_LOW = 4
    SDA_HIGH = 5
    SDN_HIGH = 6
    SRD_MULTICAST = 7
    FDL_STATUS = 9
    TIME_EVENT_2 = 10
    SRD_LOW = 12
    SRD_HIGH = 13
    IDENT = 14
    LSAP_STATUS = 15


class Status(enum.IntEnum):
    """Response (acknowledgement) codes, FC bits 0-3 with bit 6 clear."""

    OK = 0
    UE = 1  # user error
    RR = 2  # no resources
    RS = 3  # SAP not activated
    DL = 8  # response data low
    NR = 9  # no response data
    DH = 10  # response data high (diagnosis waiting)
    RDL = 12  # response data low, no resources
    RDH = 13  # response data high, no resources


class StationType(enum.IntEnum):
    """FC bits 4-5 of a response."""

    SLAVE = 0
    MASTER_NOT_READY = 1
    MASTER_READY = 2
    MASTER_IN_RING = 3


def request_fc(function: Function, *, fcb: bool = False, fcv: bool = False) -> int:
    """The FC byte of a request."""
    return _FC_REQUEST | (_FC_FCB if fcb else 0) | (_FC_FCV if fcv else 0) | int(function)


def response_fc(status: Status, station: StationType = StationType.SLAVE) -> int:
    """The FC byte of a response."""
    return (int(station) << 4) | int(status)


@dataclass(frozen=True, slots=True)
class FrameControl:
    """A decoded FC byte."""

    raw: int

    @property
    def is_request(self) -> bool:
        return bool(self.raw & _FC_REQUEST)

    @property
    def fcb(self) -> bool:
        return self.is_request and bool(self.raw & _FC_FCB)

    @property
    def fcv(self) -> bool:
        return self.is_request and bool(self.raw & _FC_FCV)

    @property
    def function(self) -> Function | None:
        """The request function; None for a response or an unknown function."""
        if not self.is_request:
            return None
        try:
            return Function(self.raw & 0x0F)
        except ValueError:
            return None

    @property
    def status(self) -> Status | None:
        """The response code; None for a request or an unknown code."""
        if self.is_request:
            return None
        try:
            return Status(self.raw & 0x0F)
        except ValueError:
            return None

    @property
    def station_type(self) -> StationType | None:
        if self.is_request:
            return None
        return StationType(self.raw >> 4 & 0x03)


# ------------------------------------------------------------------- frames


@dataclass(frozen=True, slots=True)
class Frame:
    """Base of every FDL frame."""


@dataclass(frozen=True, slots=True)
class ShortAck(Frame):
    """SC (E5): a short acknowledge."""


@dataclass(frozen=True, slots=True)
class Token(Frame):
    """SD4: the token from ``sa`` to ``da``."""

    da: int
    sa: int


@dataclass(frozen=True, slots=True)
class DataFrame(Frame):
    """SD1, SD2 or SD3: the encoder picks SD1 without data, SD3 for 8 data bytes
    without SAPs, SD2 otherwise."""

    da: int
    sa: int
    fc: int
    dsap: int | None = None
    ssap: int | None = None
    data: bytes = b""

    @property
    def control(self) -> FrameControl:
        return FrameControl(self.fc)

    @property
    def body_length(self) -> int:
        """LE: DA, SA, FC, the SAP bytes and the data."""
        saps = (self.dsap is not None) + (self.ssap is not None)
        return 3 + saps + len(self.data)


def fcs(data: bytes | bytearray | memoryview) -> int:
    """The frame check sequence: arithmetic sum modulo 256."""
    return sum(data) & 0xFF


def _check_address(name: str, value: int) -> None:
    if not 0 <= value <= BROADCAST:
        raise LocalProtocolError(f"{name} {value} is outside 0-127")


def _check_sap(name: str, value: int | None) -> None:
    if value is not None and not 0 <= value <= MAX_SAP:
        raise LocalProtocolError(f"{name} {value} is outside 0-63")


def encode(frame: Frame) -> bytes:
    """The bytes of ``frame``; a clear error for what FDL cannot carry."""
    if isinstance(frame, ShortAck):
        return bytes((SC,))
    if isinstance(frame, Token):
        _check_address("token DA", frame.da)
        _check_address("token SA", frame.sa)
        return bytes((SD4, frame.da, frame.sa))
    if not isinstance(frame, DataFrame):
        raise LocalProtocolError(f"{type(frame).__name__} is not an FDL frame")
    _check_address("DA", frame.da)
    _check_address("SA", frame.sa)
    _check_sap("DSAP", frame.dsap)
    _check_sap("SSAP", frame.ssap)
    if not 0 <= frame.fc <= 0xFF:
        raise LocalProtocolError(f"FC {frame.fc} is not a byte")
    le = frame.body_length
    if le > MAX_LE:
        raise LocalProtocolError(f"{len(frame.data)} data bytes do not fit one frame (LE {le})")
    body = bytearray(
        (
            frame.da | (_EXT if frame.dsap is not None else 0),
            frame.sa | (_EXT if frame.ssap is not None else 0),
            frame.fc,
        )
    )
    if frame.dsap is not None:
        body.append(frame.dsap)
    if frame.ssap is not None:
        body.append(frame.ssap)
    body += frame.data
    tail = bytes((fcs(body), ED))
    if le == 3:
        return bytes((SD1,)) + body + tail
    if frame.dsap is None and frame.ssap is None and len(frame.data) == SD3_DATA:
        return bytes((SD3,)) + body + tail
    return bytes((SD2, le, le, SD2)) + body + tail


def decode_body(body: bytes) -> DataFrame:
    """DA..data of an SD1/SD2/SD3 frame (FCS already checked) as a :class:`DataFrame`."""
    if len(body) < 3:
        raise RemoteProtocolError(f"frame body of {len(body)} bytes (DA, SA, FC at least)")
    da, sa, fc = body[0], body[1], body[2]
    pos = 3
    dsap = ssap = None
    if da & _EXT:
        dsap, pos = _sap(body, pos, "DSAP")
    if sa & _EXT:
        ssap, pos = _sap(body, pos, "SSAP")
    return DataFrame(da & 0x7F, sa & 0x7F, fc, dsap, ssap, bytes(body[pos:]))


def _sap(body: bytes, pos: int, name: str) -> tuple[int, int]:
    if pos >= len(body):
        raise RemoteProtocolError(f"address extension announces a {name} the frame lacks")
    byte = body[pos]
    if byte & 0xC0:
        raise RemoteProtocolError(f"{name} byte {byte:#04x} uses segment addressing")
    return byte, pos + 1
