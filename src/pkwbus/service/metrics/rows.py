"""The lines of each entry of a mapping (a reading of the snapshot, a drive's state), in
the mapping's order, kept in columns (one per family) that a scrape joins.

An entry's row is made when its object lands (:meth:`Rows.update`), or at the scrape
when the object the mapping holds then is not the one its row was made of
(:meth:`Rows.sync` compares them by identity, in C, and makes only those again): a
row never shows an object the mapping no longer holds. The objects are immutable (a
frozen ``Reading``, ``DriveState``): a new value is a new object.

The keys (the layout) are listed and compared only when something says they may
have changed: another size, a key landed that has no row yet, another last key, or an
object other than its row's at some place (one pass in C; a 10,080-key list compared
at every scrape cost more). A key that comes goes to the end of a dict: keys replaced
while every place holds the object its row was made of and the last key stays would
take a key gone and the keys after it put back with the very objects they held, which
no writer does (a writer lands a reading when it makes it).

Each column is joined in pieces of ``chunk`` rows, and a piece is joined again only
when one of its texts in that column is another since (a row made again keeps the
texts that did not change, the same objects): values that landed together (a drive's,
a line's round) leave the other pieces as they were, and a drive whose main actual
value moved leaves its status bits' piece as it was.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from itertools import compress
from operator import is_not
from typing import Generic, TypeVar

__all__ = ["Made", "Rows"]

K = TypeVar("K", bound=Hashable)
S = TypeVar("S")

Made = tuple[bytes, ...]  # a row: its text in each column
_STALE = object()  # the object of a row that must be made again (its heads changed)


class Rows(Generic[K, S]):
    """Rows of ``columns`` texts, made by ``make(key, object, previous)``; ``previous``
    is the object and row the key had before (None: none, or one to forget), for a
    row to reuse what did not change."""

    __slots__ = ("_at", "_chunk", "_columns", "_dirty", "_early", "_joined", "_keys",
                 "_made", "_make", "_objects", "_rows")  # fmt: skip

    def __init__(
        self, columns: int, make: Callable[[K, S, tuple[S, Made] | None], Made], chunk: int
    ) -> None:
        self._make = make
        self._chunk = chunk
        self._keys: list[K] = []
        self._at: dict[K, int] = {}
        self._objects: list[object] = []  # the object each row was made of
        self._rows: list[Made] = []  # each row as made (its texts are in the columns)
        self._columns: list[list[bytes]] = [[] for _ in range(columns)]
        # Each column's pieces as joined, and the pieces of each column to join again.
        self._joined: list[list[bytes]] = [[] for _ in range(columns)]
        self._dirty: list[set[int]] = [set() for _ in range(columns)]
        # Rows of keys not in the columns yet (landed since the last scrape).
        self._early: dict[K, tuple[S, Made]] = {}
        self._made = 0

    @property
    def made(self) -> int:
        """How many rows were made since the start (for tests)."""
        return self._made

    def update(self, key: K, obj: S) -> None:
        """``key`` holds ``obj`` now: its row is made now."""
        at = self._at.get(key)
        if at is None:
            self._made += 1
            self._early[key] = (obj, self._make(key, obj, self._early.get(key)))
        else:
            self._put(at, key, obj)

    def drop(self, key: K) -> None:
        """``key``'s row is made anew, without its previous one, when next needed."""
        self._early.pop(key, None)
        at = self._at.get(key)
        if at is not None:
            self._objects[at] = _STALE

    def sync(self, entries: dict[K, S]) -> list[list[bytes]]:
        """The text of ``entries`` as they are now, in their order: each column's pieces
        (of ``chunk`` rows each; they stay as they are when rows change later)."""
        keys = self._keys
        if (
            len(entries) != len(keys)
            or self._early
            or (keys and next(reversed(entries)) is not keys[-1])
            or any(map(is_not, entries.values(), self._objects))
        ):
            self._check(entries)
        chunk = self._chunk
        for column, joined, dirty in zip(self._columns, self._joined, self._dirty, strict=True):
            for n in dirty:
                start = n * chunk
                joined[n] = b"".join(column[start : start + chunk])
            dirty.clear()
        return [joined[:] for joined in self._joined]

    def _check(self, entries: dict[K, S]) -> None:
        """Keys or objects other than the rows': the keys compared, then the objects."""
        keys = list(entries)
        if keys != self._keys:
            self._lay_out(keys, list(entries.values()))
            return
        self._early.clear()  # landed, but not held (it would be among the keys)
        objects = list(entries.values())
        for at in compress(range(len(objects)), map(is_not, objects, self._objects)):
            self._put(at, keys[at], objects[at])

    def _put(self, at: int, key: K, obj: S) -> None:
        old = self._objects[at]
        self._made += 1
        row = self._make(key, obj, None if old is _STALE else (old, self._rows[at]))  # type: ignore[arg-type]
        self._objects[at] = obj
        self._rows[at] = row
        n = at // self._chunk
        for column, text, dirty in zip(self._columns, row, self._dirty, strict=True):
            if column[at] is not text:  # a text kept from the previous row: its piece too
                column[at] = text
                dirty.add(n)

    def _lay_out(self, keys: list[K], objects: list[S]) -> None:
        """Keys came or went: the columns in the new order, each row kept when its key
        holds the same object."""
        at, early = self._at, self._early
        old_objects, old_rows = self._objects, self._rows
        rows: list[Made] = []
        for key, obj in zip(keys, objects, strict=True):
            was = at.get(key)
            if was is not None and old_objects[was] is obj:
                rows.append(old_rows[was])
                continue
            kept = early.get(key)
            if kept is not None and kept[0] is obj:
                rows.append(kept[1])
                continue
            if was is not None and old_objects[was] is not _STALE:
                kept = (old_objects[was], old_rows[was])  # type: ignore[assignment]
            self._made += 1
            rows.append(self._make(key, obj, kept))
        early.clear()
        self._keys = keys
        self._at = {key: n for n, key in enumerate(keys)}
        self._objects = list(objects)
        self._rows = rows
        width = len(self._columns)
        self._columns = [list(texts) for texts in zip(*rows, strict=True)] if rows else []
        self._columns = self._columns or [[] for _ in range(width)]
        pieces = -(-len(rows) // self._chunk)
        self._joined = [[b""] * pieces for _ in range(width)]
        self._dirty = [set(range(pieces)) for _ in range(width)]
