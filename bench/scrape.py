"""The /metrics scrape at plant scale, without a bus: 4 lines x 126 drives x 20 values.

The service's registry is built as ``pkwbus run`` builds it (``assemble`` from a
configuration with benchmark 6's twenty parameters on every FC drive, the
catalog's counters off as in ``bench/plant_scale.py``; and, unless
``--no-memory``, the history's families as ``remember`` adds them: the newest
entry of each drive's logs, the end of each drive's settings sweep, the event
loop's lag histogram), but no line runs: the readings land as a line's snapshot
writer lands them (into the snapshot, then ``ValueLanded`` to the lines'
outputs: the values' collector, the alarm board, the trends), and each poll
counts as its line's metrics count it (an exchange, a read job, its duration).

Between two scrapes a quarter of the values land anew, as at plant scale with a
poll every 20 s and Prometheus scraping every 5 s (a third of them with another
value, the others the same value at a new time), spread over every drive, and
the drives' main actual values move. Timed: ``exposition.render(registry)``,
what ``GET /metrics`` awaits, per 1,000 values (``pkwbus_parameter_value``
series), median of ``--repeat`` scrapes after one that makes the caches (wall
and CPU time; also with nothing new and with every value new); the size of the
text; then, unless ``--no-http``, ``GET /metrics`` from a client in another
process through the service's app on uvicorn (a quarter of the values landing
meanwhile, in slices). ``--families``: each collector's CPU time;
``--profile``: a cProfile of the scrapes; ``--gzip``: the CPU time of compressing the
body as ``Content-Encoding: gzip`` would (zlib levels 1 and 6), beside the render's,
and the share of the size left.

    .venv/bin/python -m bench.scrape [--lines 4] [--drives 126] [--repeat 15]
        [--no-memory] [--no-http] [--families] [--profile] [--gzip]
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import gc
import math
import pstats
import statistics
import tempfile
import time
import zlib
from pathlib import Path
from typing import Any

from bench._common import http_client, service_config
from bench._measure import markdown_table
from bench.scale import PARAMETERS
from pkwbus.master.events import Exchanged, JobDone, ValueLanded
from pkwbus.master.planning.jobs import JobKind, JobResult
from pkwbus.master.planning.outcomes import Heard
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import DriveState
from pkwbus.service.assembly.build import Parts, assemble
from pkwbus.service.config import parse_config
from pkwbus.service.metrics.exposition import MetricsRegistry, render
from pkwbus.service.runtime import Runtime

GOAL_MS_PER_1000 = 1.0
SHARE = 4  # a quarter of the values land anew between two scrapes (polls 20 s, scrapes 5 s)
T0 = 1_790_000_000.0
# Seconds between two GETs of the HTTP client; a quarter of the values lands meanwhile,
# a few at a time (five times the plant's rate of 10,080 values every 20 s).
GAP = 1.0


class Plant:
    """The service's registry and snapshot at scale, its readings landed by hand."""

    def __init__(self, runtime: Runtime, parts: Parts) -> None:
        self.runtime = runtime
        self.parts = parts
        self.keys = list(parts.collector._parameters)  # every polled (drive, parameter, index)
        self.line_of = dict(parts.line_of)
        self.round = 0

    def land(self, share: int = 1, part: slice | None = None) -> int:
        """One in ``share`` of the values (of the keys in ``part``, all when None) lands
        anew (all when 1), each as one poll; the number landed. A new round starts with
        ``part`` None or at 0."""
        snap, outputs, counts = self.runtime.snapshot, self.parts.outputs, self.parts.counts
        part = part or slice(0, len(self.keys))
        if not part.start:
            self.round += 1
        n, t = self.round, T0 + self.round * 5.0
        landed = 0
        drives: set[str] = set()
        for i in range(part.start or 0, min(part.stop, len(self.keys))):
            if share > 1 and (i + n) % share:
                continue
            key = self.keys[i]
            drive, parameter, _ = key
            if parameter.startswith("16-9"):  # alarm and warning words: now and then a bit
                value: float | int = (1 << (i % 7)) if (i + n) % 29 == 0 else 0
            elif i % 3 == 0:
                value = round(50.0 + (i % 97) * 0.1 + (n % 2) * 0.1, 1)  # moves every landing
            else:
                value = i % 1000  # the same value at a new time
            reading = Reading(value, int(value), t + (i % 1000) * 0.001)
            snap.readings[key] = reading
            line = counts[self.line_of[drive]]
            line.on_events([Exchanged(drive, None, 0.004, 0.003),
                            JobDone(drive, JobKind.READ, JobResult(Heard()))])  # fmt: skip
            outputs.on_events([ValueLanded(key, reading)])
            drives.add(drive)
            landed += 1
        for drive in drives:  # FC: a status word and main actual value with every answer
            number = int(drive.rsplit("d", 1)[1])
            snap.drives[drive] = DriveState(True, 0x0F07, t, (0x2000 + n * 13 + number) & 0xFFFF)
        for line in counts:
            snap.lines[line] = True
        return landed


async def build(lines: int, drives: int, memory: bool, tmp: str) -> Plant:
    ports = [f"/dev/pkwbus-bench-no-port-{i}" for i in range(lines)]
    text = service_config(ports, drives=drives, pnus=PARAMETERS, every="20s", baudrate=115200,
                          audit_db=f"{tmp}/audit.sqlite")  # fmt: skip
    text = text.replace("    protocol: fc\n", "    protocol: fc\n    counters: off\n")
    config = parse_config(text)
    runtime, parts = await assemble(config)
    if memory:
        from pkwbus.service.assembly.history import remember
        from pkwbus.service.history.store import HistoryStore
        from pkwbus.service.metrics.event_loop import lag_histogram

        held = remember(config, runtime, HistoryStore(Path(tmp) / "history.sqlite"))
        if held.logs is not None:  # what the log watcher shows at its start
            kinds = [(w.line, w.drive, k.value) for w in held.logs.watched for k in w.log.kinds]
            await held.stream.start(kinds)
        if held.settings is not None:  # every drive swept once
            for s in held.settings.swept.values():
                held.settings.swept_at.labels(s.line, s.drive).set(T0)
        lag_histogram(runtime.registry).observe(0.0004)
    return Plant(runtime, parts)


def _families(registry: MetricsRegistry, rounds: int, plant: Plant) -> list[dict[str, Any]]:
    """Each collector's part of the scrape: its families, series, CPU ms (median)."""
    times: dict[int, list[float]] = {}
    rows: dict[int, dict[str, Any]] = {}
    for _ in range(rounds):
        plant.land(SHARE)
        for n, collector in enumerate(registry.collectors()):
            t0 = time.process_time()
            text = b"".join(registry.exposition_of(collector))
            times.setdefault(n, []).append(time.process_time() - t0)
            names = [ln.split(b" ")[2] for ln in text.split(b"\n") if ln.startswith(b"# TYPE")]
            series = sum(1 for ln in text.split(b"\n") if ln and not ln.startswith(b"#"))
            rows[n] = {"families": b", ".join(names).decode(), "series": series,
                       "kib": len(text) / 1024}  # fmt: skip
    out = []
    for n, row in rows.items():
        row["ms"] = statistics.median(times[n]) * 1e3
        out.append(row)
    return sorted(out, key=lambda r: -r["ms"])


async def _http(plant: Plant, repeat: int, tmp: str) -> list[float]:
    """``repeat`` GET /metrics from a client in another process (``GAP`` apart, a quarter
    of the values landing in between, a few at a time), through the service's app on
    uvicorn."""
    import uvicorn

    from pkwbus.service.assembly.serve import bind
    from pkwbus.service.audit.log import AuditLog
    from pkwbus.service.http.api import create_app

    audit = AuditLog(f"{tmp}/http-audit.sqlite")
    sock = bind("127.0.0.1", 0)
    config = uvicorn.Config(create_app(plant.runtime, audit=audit), log_config=None,
                            access_log=False, lifespan="off")  # fmt: skip
    server = uvicorn.Server(config)
    task = asyncio.create_task(server.serve(sockets=[sock]))

    async def landing() -> None:  # a quarter of the values each GAP, in small slices
        step = 40  # keys: some 10 values landing at a time
        slices = max(1, len(plant.keys) // step)
        while True:
            for start in range(0, len(plant.keys), step):
                plant.land(SHARE, slice(start, start + step))
                await asyncio.sleep(GAP / slices)

    lander = asyncio.create_task(landing())
    try:
        while not server.started:
            await asyncio.sleep(0.01)
        base = f"http://127.0.0.1:{sock.getsockname()[1]}"
        got = await http_client("scrape", base, str(repeat + 1), str(GAP))
    finally:
        lander.cancel()
        server.should_exit = True
        await task
        audit.close()
        sock.close()
    return [float(t) for t in got["latencies"][1:]]  # type: ignore[index]


async def measure(
    lines: int = 4,
    drives: int = 126,
    repeat: int = 15,
    *,
    memory: bool = True,
    http: bool = True,
    families: bool = False,
    profile: bool = False,
    gzip: bool = False,
) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        plant = await build(lines, drives, memory, tmp)
        registry = plant.runtime.registry
        assert isinstance(registry, MetricsRegistry)
        plant.land()  # every value, once
        gc.collect()
        gc.freeze()  # as pkwbus run settles its heap (serve.settle_heap)
        body = await render(registry)  # the first scrape: the caches are made
        times: dict[str, list[float]] = {"quarter": [], "none": [], "all": []}
        cpu: list[float] = []
        profiler = cProfile.Profile() if profile else None
        for _ in range(repeat):
            for case, share in (("quarter", SHARE), ("none", 0), ("all", 1)):
                if share:
                    plant.land(share)
                if profiler is not None and case == "quarter":
                    profiler.enable()
                t0, c0 = time.perf_counter(), time.process_time()
                body = await render(registry)
                times[case].append(time.perf_counter() - t0)
                if case == "quarter":
                    cpu.append(time.process_time() - c0)
                if profiler is not None:
                    profiler.disable()
        values = body.count(b"\npkwbus_parameter_value{")
        packed = _gzip(body, repeat) if gzip else {}
        parts = _families(registry, repeat, plant) if families else []
        gets = await _http(plant, repeat, tmp) if http else []
        gc.unfreeze()
    if profiler is not None:
        pstats.Stats(profiler).sort_stats("tottime").print_stats(25)
    per_k = {case: statistics.median(t) * 1e3 / (values / 1000) for case, t in times.items()}
    http_k = statistics.median(gets) * 1e3 / (values / 1000) if gets else math.nan
    return {
        "values": values,
        "series": sum(1 for ln in body.split(b"\n") if ln and not ln.startswith(b"#")),
        "size_kib": len(body) / 1024,
        "ms": statistics.median(times["quarter"]) * 1e3,
        "best_ms": min(times["quarter"]) * 1e3,
        "per_1000": per_k["quarter"],
        "cpu_per_1000": statistics.median(cpu) * 1e3 / (values / 1000),
        "per_1000_none": per_k["none"],
        "per_1000_all": per_k["all"],
        "http_per_1000": http_k,
        "met": "yes" if max(per_k["quarter"], http_k if gets else 0) <= GOAL_MS_PER_1000 else "no",
        **packed,
        "families": parts,
    }


def _gzip(body: bytes, repeat: int) -> dict[str, float]:
    """CPU ms (median of ``repeat``) to gzip ``body`` at zlib levels 1 and 6, and the
    share of its size each leaves."""
    out: dict[str, float] = {}
    for level in (1, 6):
        times = []
        for _ in range(repeat):
            c0 = time.process_time()
            packed = zlib.compress(body, level, wbits=31)  # the gzip format
            times.append(time.process_time() - c0)
        out[f"gzip_{level}_cpu_ms"] = statistics.median(times) * 1e3
        out[f"gzip_{level}_share"] = len(packed) / len(body)
    return out


def run(lines: int = 4, drives: int = 126, repeat: int = 15) -> dict[str, Any]:
    row = asyncio.run(measure(lines, drives, repeat))
    row["lines"] = lines
    table = markdown_table(
        [row],
        {
            "lines": "lines",
            "values": "values in /metrics",
            "series": "series",
            "size_kib": "size KiB",
            "ms": "render ms (median)",
            "best_ms": "best",
            "per_1000": "render ms per 1,000 values",
            "cpu_per_1000": "CPU ms per 1,000 values",
            "per_1000_none": "nothing new",
            "per_1000_all": "every value new",
            "http_per_1000": "GET /metrics ms per 1,000 values",
            "met": f"≤ {GOAL_MS_PER_1000} ms",
        },
        digits=2,
    )
    return {"rows": [row], "table": table}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--lines", type=int, default=4)
    parser.add_argument("--drives", type=int, default=126)
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--no-memory", action="store_true", help="without the history's families")
    parser.add_argument("--no-http", action="store_true", help="the renderer only, no GET")
    parser.add_argument("--families", action="store_true", help="each collector's time")
    parser.add_argument("--profile", action="store_true", help="cProfile of the scrapes")
    parser.add_argument("--gzip", action="store_true", help="CPU time of gzipping the body")
    args = parser.parse_args()
    row = asyncio.run(measure(args.lines, args.drives, args.repeat, memory=not args.no_memory,
                              http=not args.no_http, families=args.families,
                              profile=args.profile, gzip=args.gzip))  # fmt: skip
    for key, value in row.items():
        if key != "families":
            print(f"{key}: {value:.3f}" if isinstance(value, float) else f"{key}: {value}")
    if row["families"]:
        columns = {"families": "families", "series": "series", "kib": "KiB", "ms": "CPU ms"}
        print(markdown_table(row["families"], columns, digits=3))


if __name__ == "__main__":
    main()
