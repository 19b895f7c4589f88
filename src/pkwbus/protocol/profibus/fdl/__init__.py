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

This module gathers the frames of :mod:`pkwbus.protocol.profibus.fdl.frames` and the
deframer of :mod:`pkwbus.protocol.profibus.fdl.deframer`. Raises
:class:`~pkwbus.protocol.errors.LocalProtocolError` for a frame FDL cannot carry
(:func:`encode`) and :class:`~pkwbus.protocol.errors.RemoteProtocolError` for
bytes that are not one frame (:func:`decode`, :func:`decode_body`).
"""

from __future__ import annotations

from pkwbus.protocol.profibus.fdl.deframer import (
    BadChecksum,
    BadEnd,
    BadFrame,
    BadLength,
    Deframer,
    DeframerEvent,
    FramingError,
    Skipped,
    Truncated,
    decode,
)
from pkwbus.protocol.profibus.fdl.frames import (
    BROADCAST,
    ED,
    MAX_ADDRESS,
    MAX_FRAME,
    MAX_LE,
    MAX_SAP,
    MIN_LE,
    SC,
    SD1,
    SD2,
    SD3,
    SD3_DATA,
    SD4,
    DataFrame,
    Frame,
    FrameControl,
    Function,
    ShortAck,
    StationType,
    Status,
    Token,
    decode_body,
    encode,
    fcs,
    request_fc,
    response_fc,
)

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
    "BadChecksum",
    "BadEnd",
    "BadFrame",
    "BadLength",
    "DataFrame",
    "Deframer",
    "DeframerEvent",
    "Frame",
    "FrameControl",
    "FramingError",
    "Function",
    "ShortAck",
    "Skipped",
    "StationType",
    "Status",
    "Token",
    "Truncated",
    "decode",
    "decode_body",
    "encode",
    "fcs",
    "request_fc",
    "response_fc",
]
