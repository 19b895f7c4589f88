"""``GET /api/v1/trends`` of every drive at plant scale: how long it holds the event loop.

4 lines x 126 drives x 20 values (10,080 trends of 60 points each, every point set), in
one process: a FastAPI app with the answer as it was (the route returning the dict,
FastAPI validating it against its response model and writing the JSON) and as it is
(:class:`~pkwbus.service.http.views.trend_pieces.TrendPieces`: kept per drive, made a few
drives at a time), asked in turn through httpx's ASGI transport. A task wakes every 1 ms
and records the longest time the loop did not let it run during the request (the loop
held), and the request's process time. Three kinds of request: the first (every piece
made), again at once (nothing changed), and after one drive's value landed.

    .venv/bin/python -m bench.trends_view [--rounds 5]
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import time
from types import SimpleNamespace
from typing import Any, cast

import httpx
from fastapi import FastAPI, Response

from bench.scale import PARAMETERS
from pkwbus.master.reading import Reading
from pkwbus.service.http.views import trend_views
from pkwbus.service.http.views.trend_pieces import TrendPieces
from pkwbus.service.metrics.trends import POINTS, Trends
from pkwbus.service.runtime import Runtime

LINES, DRIVES = 4, 126


def _runtime(now: float) -> Any:
    names = [f"line{line}-drive{n}" for line in range(LINES) for n in range(DRIVES)]
    polls = [SimpleNamespace(parameter=p, index=0) for p in PARAMETERS]
    trends = Trends()
    readings: dict[tuple[str, str, int], Reading] = {}
    for i, name in enumerate(names):
        for p in PARAMETERS:
            key = (name, p, 0)
            for point in range(POINTS):  # every point of the last 15 minutes set
                at = now - (POINTS - 1 - point) * trends.step
                readings[key] = r = Reading(float(i + point) / 7, i, at)
                trends.landed(key, r)
    return SimpleNamespace(
        drives={name: SimpleNamespace(name=name, polls=polls) for name in names},
        snapshot=SimpleNamespace(readings=readings), trends=trends,
    )  # fmt: skip


def _app(runtime: Any) -> FastAPI:
    app = FastAPI()
    pieces = TrendPieces(cast(Runtime, runtime))

    @app.get("/before", response_model=dict[str, dict[str, list[float | None]]])
    async def before() -> dict[str, dict[str, list[float | None]]]:
        now = time.time()
        return {name: trend_views(runtime, name, now) for name in runtime.drives}

    @app.get("/after", response_model=dict[str, dict[str, list[float | None]]])
    async def after() -> Response:
        return Response(await pieces.every(time.time()), media_type="application/json")

    return app


async def _held(client: httpx.AsyncClient, path: str) -> tuple[float, float, int]:
    """(longest loop hold ms, process ms, bytes) of one request."""
    longest, done = 0.0, False

    async def tick() -> None:
        nonlocal longest
        last = time.perf_counter()
        while not done:
            await asyncio.sleep(0.001)
            t = time.perf_counter()
            longest = max(longest, t - last - 0.001)
            last = t

    ticker = asyncio.create_task(tick())
    await asyncio.sleep(0.005)
    cpu = time.process_time()
    r = await client.get(path)
    cpu = time.process_time() - cpu
    done = True
    await ticker
    r.raise_for_status()
    return longest * 1000, cpu * 1000, len(r.content)


async def main(rounds: int) -> None:
    runtime = _runtime(time.time())
    transport = httpx.ASGITransport(app=_app(runtime))
    rows: dict[tuple[str, str], list[tuple[float, float, int]]] = {}
    async with httpx.AsyncClient(transport=transport, base_url="http://bench") as client:
        for n in range(rounds):
            for path in ("/before", "/after"):
                if path == "/after":  # a new piece of every drive: as after a bucket
                    for name in runtime.drives:
                        runtime.trends.stamps[name] = runtime.trends.stamps.get(name, 0) + 1
                rows.setdefault((path, "first"), []).append(await _held(client, path))
                rows.setdefault((path, "again"), []).append(await _held(client, path))
                key = ("line0-drive0", PARAMETERS[0], 0)
                r = Reading(float(n), n, time.time())
                runtime.snapshot.readings[key] = r
                runtime.trends.landed(key, r)
                rows.setdefault((path, "one new"), []).append(await _held(client, path))
    print(f"{LINES} lines x {DRIVES} drives x {len(PARAMETERS)} values, {POINTS} points each,"
          f" {rounds} rounds")  # fmt: skip
    print("| route | request | loop held ms, min / median | CPU ms, min / median | KiB |")
    print("|---|---|---:|---:|---:|")
    for (path, kind), got in rows.items():
        held, cpu = [g[0] for g in got], [g[1] for g in got]
        size = got[0][2] / 1024
        print(f"| {path[1:]} | {kind} | {min(held):.1f} / {statistics.median(held):.1f} |"
              f" {min(cpu):.1f} / {statistics.median(cpu):.1f} | {size:,.0f} |")  # fmt: skip


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    asyncio.run(main(parser.parse_args().rounds))
