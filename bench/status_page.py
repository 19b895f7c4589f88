"""The status page at plant scale: how long Chromium takes to show it, and what a refresh
costs the page's main thread.

``--lines`` simulated lines (each another process, pty, wire timing at 115200 baud, 2 ms
response delay, ``--drives`` FC drives), 20 parameters polled on each drive (benchmark 6's
set), the service in this process. Once every polled parameter has a value, each value's
trend ring is filled with 15 minutes of points (the worst case for a drive's sparklines).
Then headless Chromium (Debian's ``chromium``, driven by Playwright) opens ``/``:

- **first view**: from the navigation to the moment every drive is in the overview's
  table (the rows on the screen drawn with their numbers, the others standing in as its
  height: the page draws the rows near the screen only) and the counts per line are on
  the page (wall clock of this process, checked every animation frame). The goal is 2 s.
- **open a drive**: from the page's ``openDrive`` (a click on a row) to its detail shown
  with every value and every sparkline (in the page, ``performance.now``), median of five.
- **refresh**: the page's own refresh (``refresh()``: the overview's rows changed since
  its last answer, the lines, /readyz, the open drive), called by this process once the
  page's loop is stopped, 2 s apart as the page refreshes, with a drive's detail open.
  Timed as the **main thread**'s work from the call until 150 ms after it ends (its frame
  drawn): the CPU time of the renderer's main-thread tasks in that window, from a Chromium
  trace (parsing, script, style, layout, paint, commit; unlike their wall time, not
  lengthened by other processes on the machine), their wall time beside it, the part the
  page spends applying the answers with the layout they force (in the page), and the bytes
  it fetched; medians of ten. Twice: as the page refreshes (``changed_since``), and with
  every drive's row sent again (the page's full overview, every 30 s). The goal is 100 ms.
- **sort** and **filter**, as a click and a keystroke: the page sorts every row by name,
  one way and the other (every row moves: the worst case), and filters them by a text
  (two in three hidden) and back, measured as a refresh is (main-thread CPU from the call
  until 150 ms after it); medians of six.
- the answers the page fetches (the overview, all and changed; one drive; its trends)
  and, for scale, the two it no longer fetches (every drive's full view, every drive's
  trends): fetched and parsed by the page, median of five, and their size.
- the page's element count, the overview's rows drawn (those near the screen) and the
  JavaScript heap at the end.

Also the trends' memory at 8 lines x 126 drives x 20 parameters, every ring full: what
``tracemalloc`` counts for the rings and their index (the keys are the service's own and
not counted).

``--throttle 4`` also runs the page with its CPU slowed four times (Chromium's CPU
throttling), for an old plant PC.

    .venv/bin/python -m bench.status_page [--drives 126] [--lines 1] [--throttle 1 --throttle 4]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import shutil
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

from bench._common import Service, quiet_logs, service_config
from bench._measure import BenchSetupError, markdown_table
from bench.scale import BAUD, PARAMETERS, fc_lines
from pkwbus import link
from pkwbus.master.reading import Reading
from pkwbus.service.metrics.trends import POINTS, Trends

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run",
        "--enable-precise-memory-info"]  # fmt: skip
GOAL_S = 2.0
REFRESH_GOAL_MS = 100.0
GAP_S = 2.0  # between two timed refreshes, as the page refreshes
MODES = ("changed", "full")
TRACED = ["toplevel", "blink.user_timing"]  # the main thread's tasks; the page's marks

# Every drive in the overview's table (its aria-rowcount: the head's row and a row a drive;
# the page draws the rows near the screen, the others stand in as the table's height), the
# rows on the screen drawn with their numbers, and the counts per line.
SHOWN = """([drives]) => {
  const table = document.getElementById("drives");
  const first = document.querySelector("#drives tbody tr td.age");
  return table.getAttribute("aria-rowcount") === String(drives + 1) && first !== null
    && first.textContent !== ""
    && (document.querySelector("#lines tfoot td.drives") || {}).textContent === String(drives);
}"""
# The page's loop ends at its next turn; the refresh under way is let finish. Each
# application of the answers (the overview, the lines, the open drive) is timed with the
# layout it forces.
STOP = """async () => {
  running = false;
  await new Promise((r) => setTimeout(r, 2500));
  window.applied = 0;
  for (const name of ["applyOverview", "drawLines", "fillDetail"]) {
    const plain = window[name];
    window[name] = (...args) => {
      const t = performance.now();
      plain(...args);
      void document.body.offsetHeight;
      window.applied += performance.now() - t;
    };
  }
  // Function declarations are the global object's: the page's calls take the timed ones.
  applyOverview = window.applyOverview; drawLines = window.drawLines;
  fillDetail = window.fillDetail;
}"""
OPEN = """async (name) => {
  closeDrive();
  const t = performance.now();
  const trends = trendsVersion;
  openDrive(name);
  const frame = () => new Promise((r) => requestAnimationFrame(r));
  const drawn = (points) => points.filter((v) => v !== null).length >= 2;
  for (;;) {
    const values = detail && detail.drive ? detail.drive.values.length : -1;
    const sparks = Object.values(trendData).filter(drawn).length;
    if (trendsVersion > trends && document.querySelectorAll("#detail td.value").length === values
        && document.querySelectorAll("#detail svg.spark path[d]").length === sparks) break;
    if (performance.now() - t > 60000) {
      throw new Error(`${name}: ${values} values, ${sparks} sparklines not shown in 60 s`);
    }
    await frame();
  }
  return performance.now() - t;
}"""
# One operation of the page (a refresh, a sort, a filter), marked in the trace from the
# call until 150 ms after it ends (its frame drawn): [applied ms, bytes fetched].
MARKED = """async ([what, n]) => {
  performance.clearResourceTimings();
  window.applied = 0;
  performance.mark(`${what}-${n}-start`);
  if (what === "changed") {
    await refresh();
  } else if (what === "full") {
    changesToken = "";
    await refresh();
  } else if (what === "sort") {
    chosen.sort = "name";
    chosen.descending = n % 2 === 0;
    sortRows();
    drawRows();
  } else {
    document.getElementById("filter-text").value = n % 2 ? "" : "d1";
    filtersChanged();
  }
  await new Promise((r) => setTimeout(r, 150));
  performance.mark(`${what}-${n}-end`);
  const bytes = performance.getEntriesByType("resource")
    .reduce((sum, e) => sum + e.encodedBodySize, 0);
  return [window.applied, bytes];
}"""
# The last drive's row drawn with its numbers when the table is scrolled to its end (the
# page draws the rows near the screen only).
SCROLLED = """async () => {
  window.scrollTo(0, document.body.scrollHeight);
  await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
  const last = shownRows[shownRows.length - 1];
  const shown = last.row !== null && last.row.isConnected && last.age.textContent !== ""
    && last.faults.textContent !== "";
  window.scrollTo(0, 0);
  await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
  return shown;
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
FIGURES = """() => [document.getElementsByTagName("*").length,
  performance.memory ? performance.memory.usedJSHeapSize : 0,
  document.querySelectorAll("#drives tbody tr").length]"""


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


def _main_thread(trace: bytes, what: str, marks: int) -> list[tuple[float, float]]:
    """For each marked operation: the CPU and wall milliseconds of the renderer's
    main-thread tasks that began in it."""
    doc = json.loads(trace)
    events = doc["traceEvents"] if isinstance(doc, dict) else doc
    names = [e for e in events if e.get("name") == "thread_name"]
    main = {(e["pid"], e["tid"]) for e in names if e["args"].get("name") == "CrRendererMain"}
    at = {e["name"]: e["ts"] for e in events if "blink.user_timing" in e.get("cat", "")}
    tasks = [e for e in events if e.get("name") == "ThreadControllerImpl::RunTask"
             and e.get("ph") == "X" and (e.get("pid"), e.get("tid")) in main]  # fmt: skip
    out = []
    for n in range(marks):
        start, end = at[f"{what}-{n}-start"], at[f"{what}-{n}-end"]
        inside = [e for e in tasks if start <= e["ts"] <= end]
        cpu = sum(e.get("tdur", e["dur"]) for e in inside) / 1000
        out.append((cpu, sum(e["dur"] for e in inside) / 1000))
    return out


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


async def _page(base: str, drives: int, name: str, throttle: float) -> dict[str, Any]:
    try:
        from playwright.async_api import async_playwright
    except ImportError as e:
        raise BenchSetupError("Playwright is missing: pip install playwright") from e
    if not Path(CHROMIUM).exists():
        raise BenchSetupError(f"no chromium at {CHROMIUM}: apt-get install -y chromium")
    async with async_playwright() as p:
        browser = await p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = await browser.new_page(viewport={"width": 1400, "height": 900})
            if throttle != 1:
                cdp = await page.context.new_cdp_session(page)
                await cdp.send("Emulation.setCPUThrottlingRate", {"rate": throttle})
            t0 = time.perf_counter()
            await page.goto(base + "/")
            await page.wait_for_function(SHOWN, arg=[drives], polling="raf", timeout=120_000)
            first = time.perf_counter() - t0
            if not await page.evaluate(SCROLLED):
                raise BenchSetupError("the last row's numbers were not written when scrolled to")
            opening = [await page.evaluate(OPEN, name) for _ in range(5)]
            await page.evaluate(STOP)
            timed: dict[str, list[tuple[float, float, float, float]]] = {}
            for what, times in (("changed", 10), ("full", 10), ("sort", 6), ("filter", 6)):
                await browser.start_tracing(page=page, categories=TRACED)
                found = []
                for n in range(times):
                    await asyncio.sleep(GAP_S if what in MODES else 0.3)
                    found.append(await page.evaluate(MARKED, [what, n]))
                trace = await browser.stop_tracing()
                tasks = _main_thread(trace, what, len(found))
                pairs = zip(tasks, found, strict=True)
                timed[what] = [(cpu, wall, done, size) for (cpu, wall), (done, size) in pairs]
            fetched = {}
            for key, path in (
                ("overview", "/api/v1/drives?view=overview"),
                ("drive", f"/api/v1/drives?drive={name}"),
                ("trends_drive", f"/api/v1/trends?drive={name}"),
                ("all_drives", "/api/v1/drives"),
                ("all_trends", "/api/v1/trends"),
            ):
                fetched[key] = await page.evaluate(FETCHES, path)
            elements, heap, drawn = await page.evaluate(FIGURES)
        finally:
            await browser.close()
    row: dict[str, Any] = {
        "throttle": f"{throttle:g}x",
        "first_s": first,
        "goal_met": "yes" if first < GOAL_S else "no",
        "open_ms": _median(opening),
    }
    for mode in MODES:
        cpu, wall, applied, size = zip(*timed[mode], strict=True)
        row[f"{mode}_main_ms"] = _median(list(cpu))
        row[f"{mode}_max_ms"] = max(cpu)
        row[f"{mode}_wall_ms"] = _median(list(wall))
        row[f"{mode}_apply_ms"] = _median(list(applied))
        row[f"{mode}_kb"] = _median(list(size)) / 1024
    row["refresh_met"] = "yes" if row["changed_main_ms"] < REFRESH_GOAL_MS else "no"
    row["sort_ms"] = _median([cpu for cpu, *_ in timed["sort"]])
    row["filter_ms"] = _median([cpu for cpu, *_ in timed["filter"]])
    for key, (ms, size) in fetched.items():
        row[f"{key}_ms"] = ms
        row[f"{key}_kb"] = size / 1024
    row["elements"] = elements
    row["rows_drawn"] = drawn
    row["heap_mb"] = heap / 2**20
    return row


async def _measure(
    ports: list[str], drives: int, parameters: tuple[str, ...], throttles: tuple[float, ...]
) -> list[dict[str, Any]]:
    with tempfile.TemporaryDirectory() as tmp:
        text = service_config(
            ports, drives=drives, pnus=parameters, every="1s", baudrate=BAUD,
            audit_db=f"{tmp}/audit.sqlite",
        )  # fmt: skip
        async with Service(text, nodelay=True) as service:
            runtime = service.runtime
            polled = len(ports) * drives * len(parameters)
            ready = time.perf_counter() + 120.0 + 15.0 * len(ports)
            while len(runtime.snapshot.readings) < polled:
                if time.perf_counter() > ready:
                    got = len(runtime.snapshot.readings)
                    raise BenchSetupError(f"only {got} of {polled} values read in time")
                await asyncio.sleep(0.5)
            shown = _fill_trends(runtime)
            name = f"l0d{drives}"  # the detail open: the last drive of the first line
            rows = []
            for throttle in throttles:
                row = await _page(service.base, len(ports) * drives, name, throttle)
                rows.append({"lines": len(ports), "drives": len(ports) * drives,
                             "values": shown, **row})  # fmt: skip
            return rows


def measure(
    drives: int = 126,
    throttles: tuple[float, ...] = (1.0,),
    parameters: tuple[str, ...] = PARAMETERS,
    lines: int = 1,
) -> list[dict[str, Any]]:
    """``drives`` on each of ``lines`` lines."""
    with quiet_logs(), fc_lines(lines, drives) as ports:
        return link.run(_measure(ports, drives, parameters, throttles))


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


PAGE_COLUMNS = {
    "lines": "lines",
    "drives": "drives",
    "values": "values (each with a full trend)",
    "throttle": "CPU slowed",
    "first_s": "first view s",
    "goal_met": f"< {GOAL_S:g} s",
    "open_ms": "open a drive ms",
    "changed_main_ms": "refresh: main thread CPU ms",
    "refresh_met": f"< {REFRESH_GOAL_MS:g} ms",
    "changed_max_ms": "max ms",
    "changed_wall_ms": "wall ms",
    "changed_apply_ms": "of it applying ms",
    "changed_kb": "fetched KiB",
    "full_main_ms": "all rows sent: main thread CPU ms",
    "full_wall_ms": "wall ms ",
    "full_apply_ms": "applying ms",
    "full_kb": "fetched KiB ",
    "sort_ms": "sort CPU ms",
    "filter_ms": "filter CPU ms",
    "elements": "elements",
    "rows_drawn": "rows drawn",
    "heap_mb": "JS heap MB",
}
FETCH_COLUMNS = {
    "lines": "lines",
    "drives": "drives",
    "throttle": "CPU slowed",
    "overview_ms": "overview ms",
    "overview_kb": "KiB",
    "drive_ms": "?drive= ms",
    "drive_kb": "KiB ",
    "trends_drive_ms": "trends?drive= ms",
    "trends_drive_kb": "KiB  ",
    "all_drives_ms": "not fetched: all drives ms",
    "all_drives_kb": "KiB   ",
    "all_trends_ms": "all trends ms",
    "all_trends_kb": "KiB    ",
}


def run(
    drives: int = 126, throttles: tuple[float, ...] = (1.0, 4.0), lines: int = 1
) -> dict[str, Any]:
    rows = measure(drives, throttles, lines=lines)
    table = markdown_table(rows, PAGE_COLUMNS, digits=2)
    table += "\n\n" + markdown_table(rows, FETCH_COLUMNS, digits=1)
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
    parser.add_argument("--drives", type=int, default=126, help="drives on each line")
    parser.add_argument("--lines", type=int, default=1, help="simulated lines")
    parser.add_argument("--throttle", type=float, action="append")
    args = parser.parse_args()
    try:
        print(run(args.drives, tuple(args.throttle or (1.0, 4.0)), args.lines)["table"])
    except BenchSetupError as e:
        print(f"status_page: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
