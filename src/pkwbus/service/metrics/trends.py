"""The last 15 minutes of each polled numeric value, for the status page's sparklines.

A bounded ring per value: :data:`POINTS` buckets of ``period / POINTS`` seconds
(15 s), each holding the last value that landed in it, as a 32-bit float
(``array('f')``: 4 bytes a point). At 8 lines x 126 drives x 20 parameters
that is 20,160 rings of 60 points: 8.3 MiB with their bookkeeping, about 430
bytes a value (benchmark 11, ``bench/status_page.py``);
``/metrics`` and the API keep full precision, this is for the eye only. A
bucket no value landed in stays empty (NaN), so a gap shows as a gap.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Collection, Sequence
from typing import Final

from pkwbus.master.events import Event, ValueLanded
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey

__all__ = ["PERIOD", "POINTS", "Trends"]

PERIOD: Final = 900.0  # seconds of history
POINTS: Final = 60  # buckets of PERIOD / POINTS seconds


class _Ring:
    __slots__ = ("bucket", "values")

    def __init__(self, bucket: int) -> None:
        self.values = array("f", [math.nan]) * POINTS
        self.bucket = bucket  # the bucket number of the newest point


class Trends:
    """Takes each landed reading (``landed``); gives a value's points, oldest first."""

    def __init__(self, period: float = PERIOD) -> None:
        self.step = period / POINTS
        self._rings: dict[ReadingKey, _Ring] = {}
        # Per drive, how often its points changed other than by time going on (a value
        # landed, values forgotten): a view of the points may be kept while it and the
        # bucket of now are the same.
        self.stamps: dict[str, int] = {}

    def landed(self, key: ReadingKey, reading: Reading) -> None:
        value = reading.value
        if isinstance(value, str | bool):
            return
        bucket = int(reading.timestamp // self.step)
        ring = self._rings.get(key)
        if ring is None:
            ring = self._rings[key] = _Ring(bucket)
        self._advance(ring, bucket)
        ring.values[bucket % POINTS] = float(value)
        drive = key[0]
        self.stamps[drive] = self.stamps.get(drive, 0) + 1

    def on_events(self, events: Sequence[Event]) -> None:
        """Each value that landed (an output of the lines' streams)."""
        for event in events:
            if type(event) is ValueLanded:
                self.landed(event.key, event.reading)

    def forget(self, drive: str, keep: Collection[ReadingKey] | None = None) -> None:
        """The drive's values gone (a reload), all or those not in ``keep``."""
        for key in [k for k in self._rings if k[0] == drive and (keep is None or k not in keep)]:
            del self._rings[key]
        self.stamps[drive] = self.stamps.get(drive, 0) + 1

    def points(self, key: ReadingKey, now: float) -> list[float | None]:
        """The value's points up to ``now`` (wall clock), oldest first; None where none
        landed (empty when the value never landed)."""
        ring = self._rings.get(key)
        if ring is None:
            return []
        self._advance(ring, int(now // self.step))
        newest = ring.bucket
        out: list[float | None] = []
        for n in range(newest - POINTS + 1, newest + 1):
            v = ring.values[n % POINTS]
            out.append(None if math.isnan(v) else v)
        return out

    def _advance(self, ring: _Ring, bucket: int) -> None:
        """Empty the buckets between the ring's newest and ``bucket`` (time went on)."""
        if bucket <= ring.bucket:
            return
        gap = min(bucket - ring.bucket, POINTS)
        for n in range(bucket - gap + 1, bucket + 1):
            ring.values[n % POINTS] = math.nan
        ring.bucket = bucket
