"""The status page at 126 drives: how long Chromium takes to show it, and to redraw it.

One simulated line (another process, pty, wire timing at 115200 baud, 2 ms
response delay, 126 FC drives), 20 parameters polled on each drive (benchmark
6's set), the service in this process. Once every polled parameter has a
value, each value's trend ring is filled with 15 minutes of points, so every
sparkline is drawn in full (the worst case). Then headless Chromium (Debian's
``chromium``, driven by Playwright) opens ``/``:

- **first view**: from the navigation to the moment all 126 drives and all
  their values are on the page (wall clock of this process, checked every
  animation frame). The goal is 2 s.
- **redraw**: the page's own redraw of the 126 drives (``refreshNow``) from the
  service's data of the moment (fetched before, untimed), with the style and
  layout it forces, timed in the page (``performance.now``) once the page's own
  refresh is stopped; the median of ten. Three cases: the sections kept and
  their cells filled in place, 2 s apart as the page refreshes; the same with
  every sparkline drawn anew (after the trends' refresh, every 15 s); and every
  section drawn anew (the first view, or when every drive's status changes at
  once).
- **GET /api/v1/drives** and **GET /api/v1/trends**: fetched and parsed by the
  page, median of five, and their size.
- the page's element count and JavaScript heap after the redraws.

Also the trends' memory at 8 lines x 126 drives x 20 parameters, every ring
full: what ``tracemalloc`` counts for the rings and their index (the keys are
the service's own and not counted).

``--throttle 4`` also runs the page with its CPU slowed four times
(Chromium's CPU throttling), for an old plant PC.

    .venv/bin/python bench/status_page.py [--drives 126] [--throttle 1 --throttle 4]
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import math
import shutil
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Service, service_config, sim_process
from _measure import BenchSetupError, markdown_table
from scale import BAUD, DELAY, PARAMETERS

from pkwbus import link
from pkwbus.master.snapshot import Reading
from pkwbus.service.metrics.trends import POINTS, Trends

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run",
        "--enable-precise-memory-info"]  # fmt: skip
GOAL_S = 2.0
MODES = ("kept", "trends", "anew")

# Timed in the page, once its own refresh is stopped: ten redraws of the drives, each
# with the layout it forces, from the service's data as it is then (fetched, untimed).
# "kept": the sections stay and their cells are filled, 2 s apart (the page's refresh);
# "trends": so are all the sparklines (new trends, every 15 s); "anew": every section is
# drawn anew (the first view, or every drive's status changed at once).
STOP = """async () => {
  refresh = async () => {};  // the page's loop ends at its next turn
  await new Promise((r) => setTimeout(r, 2500));
}"""
REDRAWS = """async (mode) => {
  const times = [];
  for (let i = 0; i < 10; i++) {
    await new Promise((r) => setTimeout(r, mode === "kept" ? 2000 : 50));
    lastDrives = await (await fetch("/api/v1/drives", { cache: "no-store" })).json();
    if (mode === "anew") sections = new Map();
    if (mode === "trends") trendsVersion += 1;
    const t = performance.now();
    refreshNow();
    void document.body.offsetHeight;
    times.push(performance.now() - t);
  }
  return times;
}"""
FETCHES = """async (path) => {
  const times = [];
  let size = 0;
  for (let i = 0; i < 5; i++) {
    const t = performance.now();
    const response = await fetch(path, { cache: "no-store" });
    const text = await response.text();
    JSON.parse(text);
    times.push(performance.now() - t);
    size = text.length;
  }
  times.sort((a, b) => a - b);
  return [times[2], size];
}"""
SHOWN = """([drives, values]) =>
  document.querySelectorAll("#drives .drive").length === drives &&
  document.querySelectorAll("#drives td.value").length === values &&
  document.querySelectorAll("#drives svg.spark path[d]").length === values"""
FIGURES = """() => [document.getElementsByTagName("*").length,
  performance.memory ? performance.memory.usedJSHeapSize : 0]"""


def _fill_trends(runtime: Any) -> int:
    """Give every value 15 minutes of points (a slow wave), as after a quarter of an hour."""
    trends = runtime.trends
    now = time.time()
    filled = 0
    for n, (key, reading) in enumerate(list(runtime.snapshot.readings.items())):
        if isinstance(reading.value, str | bool):
            continue
        for k in range(POINTS - 1, 0, -1):
            wave = 1.0 + 0.1 * math.sin((k + n) / 7.0)
            stamp = now - k * trends.step
            trends.landed(key, Reading(float(reading.value) * wave, reading.raw, stamp))
        filled += 1
    return filled


async def _page(base: str, drives: int, values: int, throttle: float) -> dict[str, Any]:
    try:
        from playwright.async_api import async_playwright
    except ImportError as e:
        raise BenchSetupError("Playwright is missing: pip install playwright") from e
    if not Path(CHROMIUM).exists():
        raise BenchSetupError(f"no chromium at {CHROMIUM}: apt-get install -y chromium")
    async with async_playwright() as p:
        browser = await p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = await browser.new_page(viewport={"width": 1100, "height": 800})
            if throttle != 1:
                cdp = await page.context.new_cdp_session(page)
                await cdp.send("Emulation.setCPUThrottlingRate", {"rate": throttle})
            t0 = time.perf_counter()
            await page.goto(base + "/")
            await page.wait_for_function(
                SHOWN, arg=[drives, values], polling="raf", timeout=120_000
            )
            first = time.perf_counter() - t0
            await page.evaluate(STOP)
            redraws = {m: sorted(await page.evaluate(REDRAWS, m)) for m in MODES}
            drives_ms, drives_size = await page.evaluate(FETCHES, "/api/v1/drives")
            trends_ms, trends_size = await page.evaluate(FETCHES, "/api/v1/trends")
            elements, heap = await page.evaluate(FIGURES)
        finally:
            await browser.close()
    return {
        "throttle": f"{throttle:g}x",
        "first_s": first,
        "goal_met": "yes" if first < GOAL_S else "no",
        **{f"{m}_ms": (redraws[m][4] + redraws[m][5]) / 2 for m in MODES},
        "drives_ms": drives_ms,
        "drives_kb": drives_size / 1024,
        "get_trends_ms": trends_ms,
        "trends_kb": trends_size / 1024,
        "elements": elements,
        "heap_mb": heap / 2**20,
    }


async def _measure(
    port: str, drives: int, parameters: tuple[str, ...], throttles: tuple[float, ...]
) -> list[dict[str, Any]]:
    with tempfile.TemporaryDirectory() as tmp:
        text = service_config(
            [port], drives=drives, pnus=parameters, every="1s", baudrate=BAUD,
            audit_db=f"{tmp}/audit.sqlite",
        )  # fmt: skip
        async with Service(text, nodelay=True) as service:
            runtime = service.runtime
            polled = drives * len(parameters)
            ready = time.perf_counter() + 120.0
            while len(runtime.snapshot.readings) < polled:
                if time.perf_counter() > ready:
                    got = len(runtime.snapshot.readings)
                    raise BenchSetupError(f"only {got} of {polled} values read in 120 s")
                await asyncio.sleep(0.5)
            shown = _fill_trends(runtime)
            rows = []
            for throttle in throttles:
                row = await _page(service.base, drives, shown, throttle)
                rows.append({"drives": drives, "values": shown, **row})
            return rows


def measure(
    drives: int = 126,
    throttles: tuple[float, ...] = (1.0,),
    parameters: tuple[str, ...] = PARAMETERS,
) -> list[dict[str, Any]]:
    # The simulated drives' alarms and warnings come and go: their log lines are not figures.
    logger = logging.getLogger("pkwbus")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        simulated = sim_process(
            "fc", f"1-{drives}", response_delay=DELAY, baudrate=BAUD, wire_timing=True,
            catalog="danfoss-fc",
        )  # fmt: skip
        with simulated as port:
            return link.run(_measure(port, drives, parameters, throttles))
    finally:
        logger.setLevel(level)


def trend_memory(lines: int = 8, drives: int = 126, parameters: int = 20) -> dict[str, Any]:
    """The bytes the trends hold with every value's ring full."""
    keys = [(f"l{n}d{d}", f"p{p}", 0) for n in range(lines) for d in range(drives)
            for p in range(parameters)]  # fmt: skip
    now = time.time()
    trends = Trends()
    readings = [Reading(float(k), k, now - k * trends.step) for k in range(POINTS)]
    tracemalloc.start()
    try:
        for key in keys:
            for reading in readings:
                trends.landed(key, reading)
        held, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return {
        "lines": lines, "drives": drives, "parameters": parameters, "values": len(keys),
        "mib": held / 2**20, "bytes_per_value": held / len(keys),
    }  # fmt: skip


def run(drives: int = 126, throttles: tuple[float, ...] = (1.0, 4.0)) -> dict[str, Any]:
    rows = measure(drives, throttles)
    table = markdown_table(
        rows,
        {
            "drives": "drives",
            "values": "values (each with a full trend)",
            "throttle": "CPU slowed",
            "first_s": "first view s",
            "goal_met": f"< {GOAL_S:g} s",
            "kept_ms": "redraw ms",
            "trends_ms": "with new trends ms",
            "anew_ms": "drawn anew ms",
            "drives_ms": "GET /api/v1/drives ms",
            "drives_kb": "KiB",
            "get_trends_ms": "GET /api/v1/trends ms",
            "trends_kb": "KiB ",
            "elements": "elements",
            "heap_mb": "JS heap MB",
        },
        digits=2,
    )
    memory = trend_memory()
    table += "\n\n" + markdown_table(
        [memory],
        {
            "lines": "lines", "drives": "drives per line", "parameters": "parameters per drive",
            "values": "values", "mib": "trends MiB", "bytes_per_value": "bytes per value",
        },
        digits=1,
    )  # fmt: skip
    return {"rows": rows, "table": table, "memory": memory}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--drives", type=int, default=126)
    parser.add_argument("--throttle", type=float, action="append")
    args = parser.parse_args()
    try:
        print(run(args.drives, tuple(args.throttle or (1.0, 4.0)))["table"])
    except BenchSetupError as e:
        print(f"status_page: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
