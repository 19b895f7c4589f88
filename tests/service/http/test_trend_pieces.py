"""GET /api/v1/trends in pieces: a drive's points are made again only when they changed (a
value landed, the bucket of now moved on), the answer says what the drives' trends say, and
the answer of every drive lets the loop turn while it is made."""

from __future__ import annotations

import asyncio
import json
from types import SimpleNamespace
from typing import Any, cast

from pkwbus.master.reading import Reading
from pkwbus.service.http.views import trend_views
from pkwbus.service.http.views.trend_pieces import CHUNK, TrendPieces
from pkwbus.service.metrics.trends import Trends
from pkwbus.service.runtime import Runtime

PARAMETERS = ("16-13", "16-14")
T0 = 1_000_000.0


def _runtime(drives: int) -> Any:
    """What the trends' view reads of a runtime: the drives' polls, the snapshot's readings,
    the trends (a point a second)."""
    names = [f"fan{n}" for n in range(1, drives + 1)]
    polls = [SimpleNamespace(parameter=p, index=0) for p in PARAMETERS]
    trends = Trends(period=60.0)
    readings: dict[tuple[str, str, int], Reading] = {}
    for n, name in enumerate(names):
        for p in PARAMETERS:
            readings[(name, p, 0)] = r = Reading(float(n), n, T0)
            trends.landed((name, p, 0), r)
    return SimpleNamespace(
        drives={name: SimpleNamespace(name=name, polls=polls) for name in names},
        snapshot=SimpleNamespace(readings=readings), trends=trends,
    )  # fmt: skip


def _expected(runtime: Any, now: float) -> dict[str, Any]:
    return {name: trend_views(runtime, name, now) for name in runtime.drives}


async def test_pieces_are_made_again_only_when_the_points_changed() -> None:
    runtime = _runtime(5)
    pieces = TrendPieces(cast(Runtime, runtime))
    now = T0 + 0.5
    assert json.loads(await pieces.every(now)) == _expected(runtime, now)
    assert pieces.made == 5
    assert json.loads(await pieces.every(now)) == _expected(runtime, now)
    assert pieces.made == 5, "nothing changed: every piece kept"
    # a value of fan3 landed: fan3's piece alone is made again, and shows it
    reading = Reading(42.0, 42, T0 + 0.7)
    runtime.snapshot.readings[("fan3", "16-14", 0)] = reading
    runtime.trends.landed(("fan3", "16-14", 0), reading)
    got = json.loads(await pieces.every(now))
    assert pieces.made == 6
    assert got == _expected(runtime, now) and got["fan3"]["16-14"][-1] == 42.0
    assert json.loads(pieces.one("fan3", now)) == {"fan3": got["fan3"]}
    assert pieces.made == 6
    # time went on by a bucket: every piece shows it
    later = T0 + 1.5
    got = json.loads(await pieces.every(later))
    assert pieces.made == 11
    assert got == _expected(runtime, later) and got["fan1"]["16-13"][-1] is None
    # the drive's values forgotten (a reload): its piece is made again, empty
    runtime.trends.forget("fan2")
    del runtime.snapshot.readings[("fan2", "16-13", 0)]
    del runtime.snapshot.readings[("fan2", "16-14", 0)]
    got = json.loads(await pieces.every(later))
    assert pieces.made == 12 and got["fan2"] == {}


async def test_every_drives_answer_lets_the_loop_turn() -> None:
    drives = 10 * CHUNK
    runtime = _runtime(drives)
    pieces = TrendPieces(cast(Runtime, runtime))
    turns = 0
    done = asyncio.Event()

    async def other() -> None:  # another request, a line's exchange
        nonlocal turns
        while not done.is_set():
            turns += 1
            await asyncio.sleep(0)

    task = asyncio.create_task(other())
    await asyncio.sleep(0)
    before = turns
    body = await pieces.every(T0 + 0.5)
    done.set()
    await task
    assert len(json.loads(body)) == drives
    assert turns - before >= drives // CHUNK - 1, "the loop turned while the answer was made"
