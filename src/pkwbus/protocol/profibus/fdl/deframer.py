"""The streaming PROFIBUS FDL deframer: bytes as they come off the line, in frames and errors.

:class:`Deframer` turns chunks into :class:`~pkwbus.protocol.profibus.fdl.frames.Frame`
and :class:`FramingError` events (it never raises: what is not a frame is an
event); :func:`decode` decodes exactly one frame and raises
:class:`~pkwbus.protocol.errors.RemoteProtocolError` when the bytes are not one.
Frame formats as in :mod:`pkwbus.protocol.profibus.fdl.frames` (EN 50170 vol. 2 part 4,
"telegram formats").
"""

from __future__ import annotations

from dataclasses import dataclass

from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profibus.fdl.frames import (
    BROADCAST,
    ED,
    MAX_LE,
    MIN_LE,
    SC,
    SD1,
    SD2,
    SD3,
    SD3_DATA,
    SD4,
    Frame,
    ShortAck,
    Token,
    decode_body,
    fcs,
)

__all__ = [
    "BadChecksum",
    "BadEnd",
    "BadFrame",
    "BadLength",
    "Deframer",
    "DeframerEvent",
    "FramingError",
    "Skipped",
    "Truncated",
    "decode",
]


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
