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

__all__ = ["Piece", "ValuesMade", "head_json", "json_list"]

Piece = tuple[Reading, ParameterDescription, str, bytes]  # a value's: what it was made of


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
    }  # fmt: skip
    return to_json(head)[:-1] + b","
