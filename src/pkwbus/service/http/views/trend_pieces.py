"""``GET /api/v1/trends`` in pieces: each drive's points as JSON, kept while neither the
drive's points (:attr:`Trends.stamps <pkwbus.service.runtime.Trends>`) nor the bucket of now
changed, and the answer of every drive made a few drives at a time, the loop free in between
(at 4 lines x 126 drives the whole answer is 600,000 points: made in one go it held the loop
110-260 ms, benchmark 12)."""

from __future__ import annotations

import asyncio

from pydantic_core import to_json

from pkwbus.service.http.views import trend_views
from pkwbus.service.runtime import DriveEntry, Runtime

__all__ = ["CHUNK", "TrendPieces"]

CHUNK = 8  # drives made between two turns of the loop (about 2-3 ms at 20 values each)


def _json(value: object) -> bytes:
    # Compact, as FastAPI's JSON answer has it (a point no value landed in is null).
    return to_json(value, inf_nan_mode="null")


class TrendPieces:
    """Each drive's ``"name":{points}`` as last made, and what it was made of (the entry,
    the drive's stamp, the bucket of now)."""

    def __init__(self, runtime: Runtime) -> None:
        self._runtime = runtime
        self._kept: dict[str, tuple[DriveEntry, int, int, bytes]] = {}
        self.made = 0  # drives' pieces made (not taken as kept): what the tests count

    def piece(self, name: str, now: float) -> bytes:
        """The drive's ``"name":{"parameter":[points]}`` (``name`` is a configured drive)."""
        runtime = self._runtime
        trends = runtime.trends
        entry = runtime.drives[name]
        if trends is None:
            return _json(name) + b":{}"
        stamp, bucket = trends.stamps.get(name, 0), int(now // trends.step)
        kept = self._kept.get(name)
        if kept is not None and kept[0] is entry and kept[1] == stamp and kept[2] == bucket:
            return kept[3]
        self.made += 1
        made = _json(name) + b":" + _json(trend_views(runtime, name, now))
        self._kept[name] = (entry, stamp, bucket, made)
        return made

    def one(self, name: str, now: float) -> bytes:
        """The answer for one drive."""
        return b"{" + self.piece(name, now) + b"}"

    async def every(self, now: float) -> bytes:
        """The answer for every drive, made :data:`CHUNK` drives at a time: the loop
        turns in between, so the lines' exchanges and other requests go on."""
        runtime = self._runtime
        names = list(runtime.drives)
        parts: list[bytes] = []
        for n, name in enumerate(names, 1):
            if name in runtime.drives:  # not taken away by a reload meanwhile
                parts.append(self.piece(name, now))
            if n % CHUNK == 0:
                await asyncio.sleep(0)
        for name in [k for k in self._kept if k not in runtime.drives]:
            del self._kept[name]  # drives a reload took away
        return b"{" + b",".join(parts) + b"}"
