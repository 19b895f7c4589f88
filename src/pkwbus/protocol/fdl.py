"""PROFIBUS FDL (layer 2) frames: SD1, SD2, SD3, SD4 and SC, and a streaming deframer.

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
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError

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


def decode(raw: bytes) -> Frame:
    """Decode exactly one frame; the peer's error when ``raw`` is not one."""
    deframer = Deframer()
    events = deframer.feed(raw) + deframer.flush()
    frames = [e for e in events if isinstance(e, Frame)]
    if len(frames) == 1 and len(events) == 1:
        return frames[0]
    errors = [e for e in events if isinstance(e, FramingError)]
    what = errors[0].describe() if errors else f"{len(frames)} frames"
    raise RemoteProtocolError(f"not one FDL frame: {what}")


# ----------------------------------------------------------------- deframer


@dataclass(frozen=True, slots=True)
class FramingError:
    """Base of the deframer's error events: something on the line was not a frame."""

    def describe(self) -> str:
        return type(self).__name__


@dataclass(frozen=True, slots=True)
class Skipped(FramingError):
    """Bytes passed over while hunting for a start delimiter."""

    count: int

    def describe(self) -> str:
        return f"{self.count} bytes skipped"


@dataclass(frozen=True, slots=True)
class BadLength(FramingError):
    """An SD2 header whose LE and LEr differ, lie outside 4-249, or lack the second 68."""

    header: bytes

    def describe(self) -> str:
        return f"bad SD2 header {self.header.hex(' ')}"


@dataclass(frozen=True, slots=True)
class BadChecksum(FramingError):
    raw: bytes

    def describe(self) -> str:
        return f"bad FCS in {self.raw.hex(' ')}"


@dataclass(frozen=True, slots=True)
class BadEnd(FramingError):
    """A frame whose end delimiter is not 16."""

    raw: bytes

    def describe(self) -> str:
        return f"no end delimiter in {self.raw.hex(' ')}"


@dataclass(frozen=True, slots=True)
class BadFrame(FramingError):
    """A frame with a good FCS whose content FDL does not allow."""

    raw: bytes
    reason: str

    def describe(self) -> str:
        return self.reason


@dataclass(frozen=True, slots=True)
class Truncated(FramingError):
    """A frame that stopped before its end (seen at a gap on the line)."""

    raw: bytes

    def describe(self) -> str:
        return f"truncated frame {self.raw.hex(' ')}"


DeframerEvent = Frame | FramingError

_CHECKED = frozenset({SD1, SD2, SD3})
_STARTS = bytes((SD1, SD2, SD3, SD4, SC))


class Deframer:
    """Streaming deframer: feed it chunks, get frames and error events in order.

    SD1, SD2 and SD3 carry a length, an FCS and an end delimiter; SD4 and SC
    carry nothing to check. So the deframer accepts a token or a short
    acknowledge only where the line is in step: at the start, after a gap
    (:meth:`flush`) or right after a valid frame. After garbage or a bad
    frame it hunts for a checked frame only, resuming one byte after the bad
    candidate's start, so a valid SD1/SD2/SD3 that follows garbage, a bad FCS
    or a truncated frame is never lost; a short acknowledge after garbage is
    found after the next gap (a master flushes when it sends a request).
    Bytes skipped up to the next valid frame are reported once. The buffer
    never holds more than one incomplete frame (< :data:`MAX_FRAME` bytes).
    """

    __slots__ = ("_buf", "_hunting")

    def __init__(self) -> None:
        self._buf = bytearray()
        self._hunting = False

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, chunk: bytes) -> list[DeframerEvent]:
        self._buf += chunk
        return self._parse(final=False)

    def flush(self) -> list[DeframerEvent]:
        """A gap on the line: nothing buffered can grow into a frame any more."""
        out = self._parse(final=True)
        self._hunting = False
        return out

    def reset(self) -> None:
        self._buf.clear()
        self._hunting = False

    def _parse(self, *, final: bool) -> list[DeframerEvent]:
        buf = self._buf
        out: list[DeframerEvent] = []
        size = len(buf)
        pos = 0
        skipped = 0
        while pos < size:
            start = buf[pos]
            if start not in _STARTS or (self._hunting and start not in _CHECKED):
                skipped += 1
                pos += 1
                if not self._hunting:
                    self._hunting = True
                continue
            result = self._candidate(buf, pos, size, final=final)
            if result is None:  # incomplete: wait for more bytes
                break
            event, length = result
            if isinstance(event, Frame):
                if skipped:
                    out.append(Skipped(skipped))
                    skipped = 0
                out.append(event)
                pos += length
                self._hunting = False
                continue
            if self._hunting:
                skipped += 1
            else:
                if skipped:
                    out.append(Skipped(skipped))
                    skipped = 0
                out.append(event)
                self._hunting = True
            pos += 1
        if skipped:
            out.append(Skipped(skipped))
        del buf[:pos]
        return out

    @staticmethod
    def _candidate(
        buf: bytearray, pos: int, size: int, *, final: bool
    ) -> tuple[DeframerEvent, int] | None:
        """Judge the candidate frame starting at ``pos``; None while it is incomplete."""
        start = buf[pos]
        avail = size - pos
        if start == SC:
            return ShortAck(), 1
        if start == SD4:
            if avail < 3:
                return (Truncated(bytes(buf[pos:])), 0) if final else None
            da, sa = buf[pos + 1], buf[pos + 2]
            if da > BROADCAST or sa > BROADCAST:
                return BadFrame(bytes(buf[pos : pos + 3]), "token address above 127"), 0
            return Token(da, sa), 3
        if start == SD2:
            if avail < 4:
                if avail >= 2 and not MIN_LE <= buf[pos + 1] <= MAX_LE:
                    return BadLength(bytes(buf[pos : pos + 2])), 0
                return (Truncated(bytes(buf[pos:])), 0) if final else None
            le, ler, sd = buf[pos + 1], buf[pos + 2], buf[pos + 3]
            if le != ler or sd != SD2 or not MIN_LE <= le <= MAX_LE:
                return BadLength(bytes(buf[pos : pos + 4])), 0
            head, le_total = 4, le
        elif start == SD1:
            head, le_total = 1, 3
        else:
            head, le_total = 1, 3 + SD3_DATA
        length = head + le_total + 2
        if avail < length:
            return (Truncated(bytes(buf[pos:])), 0) if final else None
        raw = bytes(buf[pos : pos + length])
        body = raw[head : head + le_total]
        if raw[-2] != fcs(body):
            return BadChecksum(raw), 0
        if raw[-1] != ED:
            return BadEnd(raw), 0
        try:
            frame = decode_body(body)
        except RemoteProtocolError as exc:
            return BadFrame(raw, str(exc)), 0
        return frame, length
