"""The watch of the drives' own logs: its share of a loaded line's time, and whether the polls
keep their intervals while it runs (goal: at most 2 % of the line).

The service as `pkwbus run` builds it (configuration, runtime, the watch of the drives'
logs), on a line at 19200 baud to three simulated drives in another process with wire
timing and a 2 ms response delay, each polling three parameters every 300 ms (the line
about two thirds busy). The same line runs twice, in turn, with ``events: off`` and
``events: auto``, every 10 s: on an FC line (``--protocol fc``, the default) each
drive's Danfoss alarm log is watched, its newest entry's code and time; on a USS line
(``--protocol uss``) each drive's SINAMICS fault buffer (r0944) and alarm buffer
(r2121), one read each, each drive warning ``--warnings-per-hour`` times (default 12,
the simulator's; each warning an alarm that comes and goes, two sweeps of the alarm
buffer); on a USS line of MICROMASTER 4 drives (``--protocol mm4``, catalog
``siemens-mm4``) each drive's fault buffer, P0952 and r0948[4], two reads
(its polls read as raw numbers: the catalog has no actual values). The drives trip at
random (the simulator's default rate), so a sweep of a fault log now and then is in the
figure too. Every log is read whole once at start,
before the window (how long that took is printed). Printed per run: the line's busy
share (``pkwbus_line_busy_seconds_total`` over the window), the polls done against
those due, and the overruns; the watch's share is the difference of the busy shares.

    .venv/bin/python -m bench.events_share [--protocol fc|uss|mm4] [--warnings-per-hour 12]
        [--seconds 60] [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from bench._common import registry_sum, sim_process
from pkwbus import link
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.assembly.history import remember
from pkwbus.service.config import parse_config
from pkwbus.service.history.store import HistoryStore

BAUDRATE = 19200
POLLS = {
    "fc": ("16-13", "16-14", "16-10"),
    "uss": ("r0021", "r0027", "r0032"),
    "mm4": ("r0021", "r0027", "r0032"),
}
CATALOGS = {"fc": "danfoss-fc", "uss": "siemens-g120", "mm4": "siemens-mm4"}
LINES = {"fc": "fc", "uss": "uss", "mm4": "uss"}  # the line's protocol of each case
EVERY = 0.3
DRIVES = (1, 2, 3)
SETTLE = 5.0  # seconds after the start before the window: the start-up sweep is over


def _config(port: str, events: str, folder: str, protocol: str = "fc") -> str:
    polls = ", ".join(f'{{parameter: "{p}", every: {EVERY * 1000:.0f}ms}}' for p in POLLS[protocol])
    catalog = CATALOGS[protocol]
    # USS: the simulator's variable PKW length (a SINAMICS drive's factory setting) given,
    # not learned: learned from a watch's word answer or a poll's double word first, the
    # requests' length would differ between the two runs, and so the line's busy share.
    pkw = ", pkw_words: 127" if LINES[protocol] == "uss" else ""
    drives = "\n".join(
        f"      - {{name: d{a}, address: {a}, catalog: {catalog}, describe: off{pkw},"
        f" poll: [{polls}]}}"
        for a in DRIVES
    )
    return f"""
listen: 127.0.0.1:0
audit_db: {folder}/audit.sqlite
lines:
  - name: bench
    port: {port}
    protocol: {LINES[protocol]}
    baudrate: {BAUDRATE}
    timeout: 200ms
    alarms: off
    events: {events}
    settings: off
    drives:
{drives}
"""


async def _run(
    port: str, events: str, seconds: float, settle: float, protocol: str
) -> dict[str, float]:
    folder = tempfile.mkdtemp(prefix="pkwbus-bench-events-")
    config = parse_config(_config(port, events, folder, protocol), environ={})
    runtime = await build_runtime(config)
    store = HistoryStore(Path(folder) / "history.sqlite")
    memory = remember(config, runtime, store)
    started = time.perf_counter()
    await runtime.start()
    registry = runtime.registry
    swept = 0.0  # how long until every log was first read whole (events: auto)
    try:
        watched = memory.logs.watched if memory.logs is not None else []
        while any(w.last_watch is None for w in watched):
            await asyncio.sleep(0.1)  # the start-up sweeps, outside the window
        swept = time.perf_counter() - started if watched else 0.0
        await asyncio.sleep(settle)
        busy0 = registry_sum(registry, "pkwbus_line_busy_seconds_total")
        jobs0 = registry_sum(registry, "pkwbus_jobs_total")
        over0 = registry_sum(registry, "pkwbus_poll_overruns_total")
        t0 = time.perf_counter()
        await asyncio.sleep(seconds)
        elapsed = time.perf_counter() - t0
        busy = registry_sum(registry, "pkwbus_line_busy_seconds_total") - busy0
        jobs = registry_sum(registry, "pkwbus_jobs_total") - jobs0
        overruns = registry_sum(registry, "pkwbus_poll_overruns_total") - over0
    finally:
        await runtime.stop()
        store.close()
    due = len(DRIVES) * len(POLLS[protocol]) * elapsed / EVERY
    return {
        "busy": busy / elapsed,
        "polls_done": jobs / due,
        "overruns": overruns,
        "startup_sweep_s": swept,
    }


def measure(
    events: str,
    seconds: float,
    settle: float = SETTLE,
    protocol: str = "fc",
    warnings_per_hour: float = 12.0,
) -> dict[str, float]:
    extra = ["--warnings-per-hour", str(warnings_per_hour)] if protocol == "uss" else []
    with sim_process(
        LINES[protocol], "1-3", response_delay=0.002, baudrate=BAUDRATE, wire_timing=True,
        catalog=CATALOGS[protocol], extra=extra,
    ) as port:  # fmt: skip
        return link.run(_run(port, events, seconds, settle, protocol))


def run(
    seconds: float = 60.0,
    repeat: int = 3,
    settle: float = SETTLE,
    protocol: str = "fc",
    warnings_per_hour: float = 12.0,
) -> dict[str, Any]:
    rows: dict[str, list[dict[str, float]]] = {"off": [], "auto": []}
    for _ in range(repeat):
        for events in ("off", "auto"):  # interleaved
            rows[events].append(measure(events, seconds, settle, protocol, warnings_per_hour))
    off = statistics.median(r["busy"] for r in rows["off"])
    on = statistics.median(r["busy"] for r in rows["auto"])
    return {
        "busy_off": off,
        "busy_auto": on,
        "watch_share": on - off,
        "polls_done_off": min(r["polls_done"] for r in rows["off"]),
        "polls_done_auto": min(r["polls_done"] for r in rows["auto"]),
        "overruns_auto": max(r["overruns"] for r in rows["auto"]),
        "startup_sweep_s": statistics.median(r["startup_sweep_s"] for r in rows["auto"]),
        "runs": rows,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--protocol", choices=sorted(POLLS), default="fc")
    parser.add_argument("--warnings-per-hour", type=float, default=12.0)
    args = parser.parse_args()
    found = run(args.seconds, args.repeat, SETTLE, args.protocol, args.warnings_per_hour)
    print(
        f"line busy, events off: {found['busy_off']:.2%}; events auto: {found['busy_auto']:.2%};"
        f" the watch's share: {found['watch_share']:.2%} of the line (goal: at most 2 %)"
    )
    print(
        f"reads done per poll due (the lowest run; with the watch its reads too): off"
        f" {found['polls_done_off']:.3f}, auto {found['polls_done_auto']:.3f}; overruns with"
        f" the watch: "
        f"{found['overruns_auto']:.0f}"
    )
    print(
        f"every log first read whole {found['startup_sweep_s']:.1f} s after the start"
        " (before the window)"
    )


if __name__ == "__main__":
    main()
