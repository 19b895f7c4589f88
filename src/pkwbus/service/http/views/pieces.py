"""The pieces a drive's JSON view is kept in between two answers of ``GET /api/v1/drives``
(:class:`~pkwbus.service.http.views.drives.DriveViews`): the values' part of a drive as
last made, the start of a view, and a JSON list joined in one copy."""

from __future__ import annotations

from pydantic_core import to_json

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey
from pkwbus.protocol.pzd import status_bits
from pkwbus.service.runtime import DriveEntry

__all__ = ["Piece", "ValuesMade", "head_json", "json_list", "piece_of", "restamped"]

# A value's piece: what it was made of (its reading, decoding and source), its JSON, and
# that JSON cut around the timestamp (a new reading of the same value differs only there).
Piece = tuple[Reading, ParameterDescription, str, bytes, bytes, bytes]

TIMESTAMP = b',"timestamp":'


def piece_of(fields: dict[str, object]) -> tuple[bytes, bytes, bytes]:
    """A value's JSON (``to_json`` of its fields, NaN and infinity as null) and that JSON cut
    before and after its timestamp."""
    piece = to_json(fields, inf_nan_mode="null")
    head, _, rest = piece.partition(TIMESTAMP)
    stamp = to_json(fields["timestamp"], inf_nan_mode="null")
    assert rest.startswith(stamp), "the timestamp comes after the unit"
    return piece, head + TIMESTAMP, rest[len(stamp) :]


def restamped(was: Piece, reading: Reading) -> bytes | None:
    """The piece of ``reading`` made from ``was`` when only the time differs (the same
    value and raw number, of the same type); None when it must be made again."""
    before = was[0]
    value = reading.value
    if type(value) is not type(before.value) or value != before.value or reading.raw != before.raw:
        return None
    return b"".join((was[4], to_json(reading.timestamp, inf_nan_mode="null"), was[5]))


class ValuesMade:
    """A drive's polls as its values are made, and what they were last made of: each
    poll's reading key, (parameter, index), parameter and source before the drive described
    it; the readings, decodings and sources seen, each value's piece (its reading, its
    decoding, its source, the JSON), and the values' JSON together."""

    __slots__ = ("ats", "entry", "fallback", "fmts", "json", "keys", "parameters", "pieces",
                 "readings", "texts", "told")  # fmt: skip

    def __init__(self, entry: DriveEntry) -> None:
        polls, name = entry.polls, entry.name
        self.entry = entry
        self.keys: list[ReadingKey] = [(name, p.parameter, p.index) for p in polls]
        self.ats: list[tuple[str, int]] = [(p.parameter, p.index) for p in polls]
        self.parameters: list[str] = [p.parameter for p in polls]
        self.fallback: list[str] = [entry.sources.get(p.parameter, "none") for p in polls]
        self.readings: list[Reading | None] = [None] * len(polls)
        self.fmts: list[ParameterDescription | None] | None = None  # None: nothing made yet
        self.told: list[str | None] | None = None
        self.pieces: list[Piece | None] = [None] * len(polls)
        self.texts: list[bytes] = [b""] * len(polls)  # each value's piece now (b"": none)
        self.json = b""


def json_list(pieces: list[bytes]) -> bytes:
    """A JSON list of the pieces, made in one copy (a large answer is megabytes)."""
    parts = [b","] * (2 * len(pieces) + 1)
    parts[0], parts[-1] = b"[", b"]"
    parts[1::2] = pieces
    return b"".join(parts) if pieces else b"[]"


def head_json(name: str, entry: DriveEntry, up: bool, word: int | None) -> bytes:
    """The start of the drive's view as JSON, up to its values (a comma last)."""
    head = {
        "name": name, "line": entry.line, "protocol": entry.target.protocol.value,
        "address": entry.target.address, "dialect": entry.target.dialect.name,
        "up": up, "status_word": word,
        "status": status_bits(word, entry.target.profile) if word is not None else {},
        "polled": len(entry.polls),
    }  # fmt: skip
    return to_json(head)[:-1] + b","
