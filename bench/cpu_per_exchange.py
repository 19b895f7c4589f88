"""CPU per exchange of the master process, side by side with pymodbus's async RTU client.

The simulated drive runs in another process on a pty with zero response
delay and no wire timing, so the line is as fast as the software on both
ends; ``time.process_time()`` here counts the master's CPU only.

(a) ``TelegramPort.exchange`` in a loop: one FC parameter read after another.
(b) the service path: a ``LineRunner`` over 3 drives whose polls are
    always due, with ``LineMetrics`` turning every event into Prometheus
    counter increments and the snapshot's collector rendering each value's
    lines as it lands, as ``pkwbus run`` does.

``--drives 1,16,126`` runs (b) with that many drives on the line instead of
3, interleaved, and prints each one's CPU per exchange against the first.

    .venv/bin/python -m bench.cpu_per_exchange [--n 5000] [--repeat 3]
    .venv/bin/python -m bench.cpu_per_exchange --drives 1,16,126 [--n 5000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
from collections.abc import Sequence
from typing import Any

from prometheus_client import CollectorRegistry

from bench._common import best_median, make_port, sim_process
from bench._measure import markdown_table, measure_cpu
from pkwbus import link
from pkwbus.master.carriers import SerialCarrier, carrier_for
from pkwbus.master.events import Event, Exchanged, JobDone
from pkwbus.master.planning.answers import Reply
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import DriveSpec, PollSpec
from pkwbus.master.runner import LineRunner
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.protocol import pkw
from pkwbus.protocol.pzd import Profile
from pkwbus.service.metrics.devices import DriveInfo, ParameterInfo, SnapshotCollector
from pkwbus.service.metrics.instrumentation import ServiceMetrics

BAUDRATE = 115200


async def raw_loop(port: str, n: int, warmup: int = 200) -> dict[str, float]:
    line = make_port(port, "fc", BAUDRATE, timeout=0.5)
    target = DriveTarget.create("fc", 1)
    telegram = SerialCarrier(target).telegram(pkw.read(target.dialect, 1613))
    await line.open()
    bad = 0
    try:
        for _ in range(warmup):
            await line.exchange(SerialCarrier(target).address, telegram)
        with measure_cpu(ops=n) as t:
            for _ in range(n):
                if not isinstance(
                    await line.exchange(SerialCarrier(target).address, telegram), Reply
                ):
                    bad += 1
    finally:
        await line.close()
    return {"cpu_us_per_op": t.cpu_us_per_op, "ops_per_s": t.ops_per_s, "errors": bad}


class Counting:
    """The line's metrics, counting exchanges and good polls on the side.

    Reading the counters back from the registry would cost the master CPU in
    proportion to the number of drives, and that is not the line's cost.
    """

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.telegrams = 0
        self.ok = 0

    def on_events(self, events: Sequence[Event]) -> None:
        for event in events:
            if isinstance(event, Exchanged):
                self.telegrams += 1
            elif isinstance(event, JobDone) and isinstance(event.result.outcome, Answered):
                self.ok += 1
        self.inner.on_events(events)


async def service_path(port: str, n: int, count: int = 3) -> dict[str, float]:
    registry = CollectorRegistry()
    metrics = ServiceMetrics(registry)
    names = [f"d{i}" for i in range(1, count + 1)]
    drives = []
    for i, name in enumerate(names, 1):
        target = DriveTarget.create("fc", i)
        polls = tuple(
            PollSpec(p, 0, pkw.read(target.dialect, int(p.replace("-", ""))), 0.0)
            for p in ("16-13", "16-14", "16-10")
        )
        drives.append(DriveSpec(name, carrier_for(target), polls))
    line = make_port(port, "fc", BAUDRATE, timeout=0.5)
    line_metrics = metrics.for_line("bench", {d.name: d.carrier.dialect for d in drives})
    counting = Counting(line_metrics)
    sched = LineRunner(
        "bench",
        line,
        ExchangeWire(line.timeout),
        drives,
        observers=[counting],
        poll_deadline=1.0,
    )
    # The device values' collector, wired as build_runtime wires it.
    infos = [
        ParameterInfo("bench", d.name, p.parameter, p.index, p.request.pnu, "", "", "u16")
        for d in drives
        for p in d.polls
    ]
    kinds = {d.name: DriveInfo("bench", Profile.FC) for d in drives}
    collector = SnapshotCollector(sched.snapshot, kinds, infos)
    registry.register(collector)
    # (A tree from before the lines were rendered as they land has no ``landed``:
    # there they were rendered at the scrape, which this benchmark does not run.)
    line_metrics.values = getattr(collector, "landed", None)

    def done() -> float:
        return counting.ok

    def telegrams() -> float:
        return counting.telegrams

    task = asyncio.create_task(sched.run())
    while telegrams() < 200:
        await asyncio.sleep(0.01)
    t0, j0 = telegrams(), done()
    with measure_cpu() as t:
        while telegrams() - t0 < n:
            await asyncio.sleep(0.005)
        t.ops = int(telegrams() - t0)
        jobs = done() - j0
    sched.stop()
    await task
    return {
        "cpu_us_per_op": t.cpu_us_per_op,
        "ops_per_s": t.ops_per_s,
        "errors": int(t.ops - jobs),
    }


def measure_pkwbus(n: int) -> dict[str, dict[str, float]]:
    out = {}
    with sim_process("fc", "1-3") as port:
        out["raw"] = link.run(raw_loop(port, n))
    with sim_process("fc", "1-3") as port:
        out["service"] = link.run(service_path(port, n))
    return out


def run(n: int = 5000, repeat: int = 3) -> dict[str, Any]:
    from bench import pymodbus_baseline

    runs: dict[str, list[dict[str, Any]]] = {"raw": [], "service": [], "pymodbus": []}
    for _ in range(repeat):
        ours = measure_pkwbus(n)
        runs["raw"].append(ours["raw"])
        runs["service"].append(ours["service"])
        runs["pymodbus"].append(pymodbus_baseline.measure(n))
    py = statistics.median(r["cpu_us_per_op"] for r in runs["pymodbus"])
    rows = []
    titles = {
        "raw": "pkwbus (a) TelegramPort.exchange loop",
        "service": "pkwbus (b) LineRunner + metrics",
        "pymodbus": runs["pymodbus"][0]["name"],
    }
    for key, results in runs.items():
        cpu = [r["cpu_us_per_op"] for r in results]
        rate = [r["ops_per_s"] for r in results]
        best, med = best_median(cpu, higher_is_better=False)
        rows.append(
            {
                "master": titles[key],
                "cpu_best": best,
                "cpu_median": med,
                "rate_median": statistics.median(rate),
                "ratio": med / py,
                "errors": sum(int(r["errors"]) for r in results),
            }
        )
    table = markdown_table(
        rows,
        {
            "master": "Master",
            "cpu_best": "CPU µs/exchange, best",
            "cpu_median": "median",
            "rate_median": "exchanges/s (median)",
            "ratio": "median / pymodbus median",
            "errors": "errors",
        },
        digits=1,
    )
    return {"rows": rows, "table": table, "n": n, "repeat": repeat}


def by_drives(n: int, repeat: int, counts: list[int]) -> dict[str, Any]:
    """CPU per exchange of the service path at each number of drives, runs interleaved."""
    cpu: dict[int, list[float]] = {c: [] for c in counts}
    for _ in range(repeat):
        for c in counts:
            with sim_process("fc", f"1-{c}") as port:
                cpu[c].append(link.run(service_path(port, n, c))["cpu_us_per_op"])
    first_median = statistics.median(cpu[counts[0]])
    first_min = min(cpu[counts[0]])
    rows = []
    for c in counts:
        best, med = best_median(cpu[c], higher_is_better=False)
        rows.append(
            {
                "drives": c,
                "cpu_best": best,
                "cpu_median": med,
                "ratio_best": best / first_min,
                "ratio_median": med / first_median,
            }
        )
    table = markdown_table(
        rows,
        {
            "drives": "drives on the line",
            "cpu_best": "CPU µs/exchange, best",
            "cpu_median": "median",
            "ratio_best": f"best / best at {counts[0]}",
            "ratio_median": f"median / median at {counts[0]}",
        },
        digits=2,
    )
    return {"rows": rows, "table": table, "n": n, "repeat": repeat, "cpu": cpu}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--n", type=int, default=5000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--only", choices=("raw", "service"), help="pkwbus only, no baseline")
    parser.add_argument("--drives", help="service path with these numbers of drives: 1,16,126")
    args = parser.parse_args()
    if args.drives:
        print(by_drives(args.n, args.repeat, [int(c) for c in args.drives.split(",")])["table"])
        return
    if args.only:
        for _ in range(args.repeat):
            with sim_process("fc", "1-3") as port:
                f = raw_loop if args.only == "raw" else service_path
                r = link.run(f(port, args.n))
            print(f"{args.only}: {r['cpu_us_per_op']:.1f} us CPU, {r['ops_per_s']:.0f}/s, {r}")
        return
    result = run(args.n, args.repeat)
    print(result["table"])


if __name__ == "__main__":
    main()
