"""The sweep of the drives' settings: its share of a line's time at the default interval on
a 126-drive line (goal: at most 5 %), and whether the polls keep their intervals while it
runs.

The service as `pkwbus run` builds it, on an FC line at 19200 baud to 126 simulated drives
in another process (wire timing, 2 ms response delay), each sweeping the 14 settings of
the danfoss-fc catalog; three of them also poll three parameters every 300 ms. A sweep
every hour reads too little for a short window, so the sweep runs faster (``--every``,
default 300 s) and the line time of one settings read is measured: the line's busy
seconds the sweep adds over the settings it read in the window (``describe: off``: no
description elements, nor the factory values and characteristics a first sweep reads
once). The share at the default interval is then reads per second at one hour
(126 x 14 / 3600) times that time. The same line runs with ``settings: off`` too,
interleaved, for the polls done against those due.

    .venv/bin/python -m bench.settings_share [--seconds 60] [--repeat 3] [--every 300]
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
DRIVES = 126
SETTINGS = 14  # of the danfoss-fc catalog
POLLED = (1, 2, 3)
POLLS = ("16-13", "16-14", "16-10")
EVERY = 0.3
DEFAULT_EVERY = 3600.0  # the settings sweep's default interval


def _config(port: str, every: float | None, folder: str, drives: int) -> str:
    polls = ", ".join(f'{{parameter: "{p}", every: {EVERY * 1000:.0f}ms}}' for p in POLLS)
    rows = []
    for a in range(1, drives + 1):
        poll = f", poll: [{polls}]" if a in POLLED else ""
        rows.append(f"      - {{name: d{a}, address: {a}, catalog: danfoss-fc{poll}}}")
    settings = "off" if every is None else f"{{every: {every:g}s}}"
    return f"""
listen: 127.0.0.1:0
audit_db: {folder}/audit.sqlite
lines:
  - name: bench
    port: {port}
    protocol: fc
    baudrate: {BAUDRATE}
    timeout: 200ms
    alarms: off
    counters: off
    events: off
    describe: off
    settings: {settings}
    drives:
{chr(10).join(rows)}
"""


def _settings_reads(runtime: Any) -> int:
    """The settings values read so far (each a read the sweep made)."""
    watcher = runtime.settings
    return 0 if watcher is None else sum(s.reads for s in watcher.swept.values())


async def _run(
    port: str, every: float | None, seconds: float, settle: float, drives: int
) -> dict[str, float]:
    folder = tempfile.mkdtemp(prefix="pkwbus-bench-settings-")
    config = parse_config(_config(port, every, folder, drives), environ={})
    runtime = await build_runtime(config)
    store = HistoryStore(Path(folder) / "history.sqlite")
    remember(config, runtime, store)
    await runtime.start()
    registry = runtime.registry
    polled = [f"d{a}" for a in POLLED if a <= drives]
    try:
        await asyncio.sleep(settle)
        busy0 = registry_sum(registry, "pkwbus_line_busy_seconds_total")
        reads0 = _settings_reads(runtime)
        lost0 = registry_sum(registry, "pkwbus_telegram_errors_total")
        polls0 = sum(registry_sum(registry, "pkwbus_telegrams_total", drive=d) for d in polled)
        over0 = registry_sum(registry, "pkwbus_poll_overruns_total")
        t0 = time.perf_counter()
        await asyncio.sleep(seconds)
        elapsed = time.perf_counter() - t0
        busy = registry_sum(registry, "pkwbus_line_busy_seconds_total") - busy0
        reads = _settings_reads(runtime) - reads0
        lost = registry_sum(registry, "pkwbus_telegram_errors_total") - lost0
        polls = (
            sum(registry_sum(registry, "pkwbus_telegrams_total", drive=d) for d in polled) - polls0
        )
        overruns = registry_sum(registry, "pkwbus_poll_overruns_total") - over0
    finally:
        await runtime.stop()
        store.close()
    due = len(polled) * len(POLLS) * elapsed / EVERY
    return {
        "busy": busy / elapsed,
        "reads": reads,
        "polls_done": polls / due if due else 0.0,
        "overruns": overruns,
        "telegram_errors": lost,
    }


def measure(
    every: float | None, seconds: float, settle: float, drives: int = DRIVES
) -> dict[str, float]:
    with sim_process(
        "fc", f"1-{drives}", response_delay=0.002, baudrate=BAUDRATE, wire_timing=True,
        catalog="danfoss-fc",
    ) as port:  # fmt: skip
        return link.run(_run(port, every, seconds, settle, drives))


def run(
    seconds: float = 60.0,
    repeat: int = 3,
    every: float = 300.0,
    settle: float | None = None,
    drives: int = DRIVES,
) -> dict[str, Any]:
    settle = 30.0 if settle is None else settle  # the line settled, every drive reading
    rows: dict[str, list[dict[str, float]]] = {"off": [], "on": []}
    for _ in range(repeat):
        rows["off"].append(measure(None, seconds, settle, drives))
        rows["on"].append(measure(every, seconds, settle, drives))
    pairs = list(zip(rows["on"], rows["off"], strict=True))
    # The busy seconds the sweep adds, over the settings reads done in the window.
    per_read = [
        max(0.0, on["busy"] - off["busy"]) * seconds / on["reads"]
        for on, off in pairs
        if on["reads"]
    ]
    read_seconds = statistics.median(per_read) if per_read else 0.0
    rate = drives * SETTINGS / DEFAULT_EVERY
    return {
        "read_seconds": read_seconds,
        "share_default": rate * read_seconds,
        "share_measured": statistics.median(on["busy"] - off["busy"] for on, off in pairs),
        "every": every,
        "polls_done_off": min(r["polls_done"] for r in rows["off"]),
        "polls_done_on": min(r["polls_done"] for r in rows["on"]),
        "overruns_on": max(r["overruns"] for r in rows["on"]),
        "telegram_errors_on": max(r["telegram_errors"] for r in rows["on"]),
        "runs": rows,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--every", type=float, default=300.0)
    args = parser.parse_args()
    found = run(args.seconds, args.repeat, args.every)
    print(
        f"one settings read: {found['read_seconds'] * 1000:.1f} ms of the line; the sweep every"
        f" {found['every']:g} s: {found['share_measured']:.2%} of the line; at the default"
        f" hour, {DRIVES} drives x {SETTINGS} settings: {found['share_default']:.2%}"
        " (goal: at most 5 %)"
    )
    print(
        f"polls done per poll due (the lowest run): settings off {found['polls_done_off']:.3f},"
        f" on {found['polls_done_on']:.3f}; overruns with the sweep: {found['overruns_on']:.0f},"
        f" telegram errors: {found['telegram_errors_on']:.0f}"
    )


if __name__ == "__main__":
    main()
