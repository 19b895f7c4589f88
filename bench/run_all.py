"""Run every benchmark and write docs/benchmarks.md (``make bench``).

    .venv/bin/python -m bench.run_all [--quick] [--only N] [--list] [--out docs/benchmarks.md]

from the repository's root (``bench`` is a package). ``--quick`` runs each benchmark in a
short form; the default takes a few minutes; ``--list`` prints the numbered benchmarks
and runs none. The figures are noisy on a shared machine:
each benchmark repeats its runs and reports the best and the median.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench import (
    connection_flood,
    cpu_per_exchange,
    dead_drive,
    ds47,
    floor,
    line_efficiency,
    mqtt_fast_path,
    mqtt_line,
    mqtt_publish,
    mqtt_throughput,
    pkw_lag,
    plant_scale,
    scale,
    scrape,
    sim_cpu,
    standby_marks,
    status_page,
    value_path,
    write_latency,
)
from bench._common import machine

ROOT = Path(__file__).resolve().parent.parent

Plan = list[tuple[str, str, Callable[[], dict[str, Any]]]]


def plan(quick: bool) -> Plan:
    q = quick
    return [
        (
            "1. Line efficiency",
            "Simulator in another process with wire timing and a 2 ms response delay; "
            "jobs back to back on a command's line session, "
            "FC parameter telegrams of 16 bytes each way. "
            "Theoretical rate = 1 / (16·11/baud + 3.5·11/baud + 2 ms + 16·11/baud).",
            lambda: line_efficiency.run(2.0 if q else 5.0, 2 if q else 3),
        ),
        (
            "2. CPU per exchange of the master process",
            "Simulator in another process on a pty, zero response delay, no wire timing; "
            "`time.process_time()` of the master only. pymodbus: async RTU client against "
            "its own RTU server over a socat pty pair, in the same run.",
            lambda: cpu_per_exchange.run(1500 if q else 5000, 2 if q else 3),
        ),
        (
            "3. Dead-drive cost",
            "4 FC drives at 115200 baud (wire timing, 2 ms delay), 3 parameters each every "
            "100 ms; completed polls/s of the 3 healthy drives.",
            lambda: dead_drive.run(4.0 if q else 10.0, 1 if q else 3),
        ),
        (
            "4. PKW lag",
            "4 USS drives at 115200 baud (wire timing, 2 ms delay) answering late; "
            "`LineRunner` interleaving against a command's line session, one job after another.",
            lambda: pkw_lag.run(2.0 if q else 5.0, 1 if q else 3),
        ),
        (
            "5. Write latency",
            "HTTP PUT from a client in another process to the service (in this process), "
            "3 drives whose polls keep the line saturated; in units of one exchange time.",
            lambda: write_latency.run(30 if q else 100),
        ),
        (
            "6. Scale",
            "126 FC drives × 20 parameters per line, each polled every second (full line load); "
            "1 line and 8 lines in one process, one simulator process per line.",
            lambda: scale.run((1, 8), 126, 4.0 if q else 10.0),
        ),
        (
            "7. Connection flood",
            "`pkwbus run` in its own process on a simulated line at full load; another "
            "process opens idle connections and sends parallel GETs; polls/s from /metrics "
            "over a connection opened before the flood.",
            lambda: connection_flood.measure(
                2000 if q else 5000, 500 if q else 2000, 2.0 if q else 5.0
            ),
        ),
        (
            "8. The floor: the start pause's wake-up",
            "The smallest asyncio master (a reader callback, the answer checked by length, "
            "BCC and address) with and without the 3.5-character start pause, pkwbus's line "
            "driven by callbacks and awaited, and pymodbus (which writes its next request "
            "at once): FC at 115200 baud on a zero-delay pty, CPU per exchange of the "
            "master, interleaved rounds.",
            lambda: floor.run(1500 if q else 5000, 2 if q else 3),
        ),
        (
            "9. CPU per exchange by the number of drives on a line",
            "Benchmark 2's service path (`LineRunner` with metrics, 3 polls per drive, "
            "always due) with 1, 16 and 126 FC drives on the line, one simulator process "
            "serving them all; rounds interleaved, each count once a round.",
            lambda: cpu_per_exchange.by_drives(1500 if q else 5000, 2 if q else 9, [1, 16, 126]),
        ),
        (
            "10. PROFIBUS DP: data record 47 against PKW in a PPO",
            "3 simulated SINAMICS slaves on a pty with wire timing, 20 parameters polled on "
            "each, always due, through the whole service; parameters/s per slave, beside what "
            "`check-config` estimates at most.",
            lambda: ds47.run(2.0 if q else 5.0),
        ),
        (
            "11. The status page at 126 drives",
            "126 simulated FC drives × 20 parameters on one line (115200 baud, wire timing), "
            "every value with 15 minutes of trend; headless Chromium opens the page. First "
            "view of every drive's row against the goal of 2 s; a drive's detail opened; a "
            "refresh's main-thread CPU (Chromium trace) against the goal of 100 ms; a sort "
            "and a filter; CPU as it is and slowed four times (the plant: --lines 8).",
            lambda: status_page.run(126, (1.0, 4.0)),
        ),
        (
            "12. Plant scale: 4 lines × 126 drives, the status page and Prometheus",
            "4 simulated lines (one process each, 115200 baud, wire timing, 2 ms delay) × 126 "
            "FC drives × 20 parameters each polled every 20 s (10,080 values), once the start's "
            "backlog has drained. Telegrams/s per line with no HTTP client and while a client "
            "in another process fetches what the status page fetches every 2 s (as it does "
            "today, and with `?view=overview&changed_since=` and one drive's detail) and "
            "another scrapes `GET /metrics` every 5 s; the service's event-loop lag (a 10 ms "
            "sleep's lateness); `GET /api/v1/drives` and `GET /metrics` ms per 1,000 values.",
            lambda: plant_scale.run(
                10.0 if q else 20.0,
                ("full",) if q else ("full", "overview"),
                3 if q else 7,
                settle=120.0 if q else 240.0,
            ),
        ),
        (
            "13. The /metrics scrape at plant scale, without a bus",
            "The service's registry as `pkwbus run` builds it (with the history's families) "
            "for 4 lines × 126 FC drives × 20 parameters (10,080 values), the readings landed "
            "by hand as a line lands them, a quarter of them anew before each scrape (polls "
            "every 20 s, Prometheus every 5 s). `exposition.render` (what `GET /metrics` "
            "awaits) per 1,000 values, median of the scrapes (also its CPU time, with nothing "
            "new and with every value new), and `GET /metrics` from a client in another "
            "process through the app on uvicorn.",
            lambda: scrape.run(4, 126, 7 if q else 15),
        ),
        (
            "14. MQTT: CPU per value published, beside the scrape's",
            "The service's runtime as benchmark 13 builds it (10,080 values), its outputs list "
            "with the MQTT output `pkwbus run` adds, connected to a local mosquitto; CPU of "
            "this process per value published on change and at a heartbeat, and per value "
            "in the scrape's render.",
            lambda: mqtt_publish.run(4, 126, 3 if q else 7),
        ),
        (
            "15. MQTT: the lines' throughput with MQTT on",
            "`pkwbus run` in its own process on 4 simulated lines (115200 baud, wire timing, "
            "2 ms delay) × 126 FC drives × 20 parameters each polled every second (full "
            "load), without `mqtt:` and with it (a local mosquitto; every value on change, "
            "deadband 0, and every 10 s; Home Assistant discovery) in turn, a fresh process "
            "each; telegrams/s of all lines once every value has landed. Goal: >= 0.98.",
            lambda: mqtt_throughput.run(1 if q else 3, 10.0 if q else 20.0),
        ),
        (
            "16. MQTT: the lines' throughput at the README's poll rate",
            "Benchmark 12's plant (4 simulated lines × 126 FC drives × 20 values every 20 s) "
            "with the MQTT output connected to a local mosquitto (started by the benchmark); "
            "once the start's backlog has drained, rounds of a window with the output taken "
            "out of the outputs list (off) then put back (on). Telegrams/s per line; goal: "
            "on / off at least 0.98.",
            lambda: mqtt_line.run(10.0 if q else 20.0, 1 if q else 3, 120.0 if q else 240.0),
        ),
        (
            "17. MQTT: the values' fast path",
            "10,080 QoS 0 values handed to a local mosquitto until the client's socket took "
            "them: pkwbus's batched path (paho's packet queue, not public) against paho's "
            "public publish and aiomqtt's awaited publish per value, side by side each round.",
            lambda: mqtt_fast_path.run(10_080, 3 if q else 7),
        ),
        (
            "18. The simulator's own CPU per telegram",
            "`Simulator.handle` on a mix of parameter reads (live and stored) and a write, "
            "in this process; then over TCP, a client in another process sending one request "
            "at a time, the simulator's process's CPU per answered telegram. It bounds how "
            "fast the benchmarks' simulated drives can answer.",
            lambda: sim_cpu.run(4000 if q else 20_000),
        ),
        (
            "19. The rooms one polled value crosses",
            "The service built from a configuration as `pkwbus run` builds it, an FC line "
            "(3 drives) and a PROFIBUS DP line in turn against a simulator in another process; "
            "every call of a pkwbus function traced (`sys.setprofile`: counts, not times) for "
            "a window of exchanges in steady state. Per exchange: the modules that ran in most "
            "exchanges, the calls that crossed into another module and into another layer, "
            "the times the path came back into `master`.",
            lambda: value_path.run(100 if q else 300),
        ),
        (
            "20. Hot standby: a held line's marks per turn",
            "One line of 126 drives, a history of 10,000 log entries and 20 swept settings a "
            "drive, a describe book of 3 models × 300 parameters, a fake etcd in memory; "
            "CPU per turn of the line's marks writer (every 2 s per held line) with nothing "
            "changed, as every turn went before the change counts and with them, and after "
            "one change of each kind.",
            lambda: standby_marks.run(turns_=10 if q else 50, repeat=1 if q else 3),
        ),
    ]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", default=str(ROOT / "docs" / "benchmarks.md"))
    parser.add_argument("--only", type=int, action="append", help="benchmark number(s)")
    parser.add_argument("--list", action="store_true", help="print the benchmarks, run none")
    args = parser.parse_args()
    if args.list:
        for title, _, _ in plan(args.quick):
            print(title)
        return 0
    info = machine()
    started = time.monotonic()
    sections = []
    for i, (title, how, fn) in enumerate(plan(args.quick), 1):
        if args.only and i not in args.only:
            continue
        print(f"== {title}", flush=True)
        t0 = time.monotonic()
        result = fn()
        print(result["table"], flush=True)
        sections.append(
            f"## {title}\n\n{how}\n\n{result['table']}\n_({time.monotonic() - t0:.0f} s)_\n"
        )
    header = (
        "# Benchmarks\n\n"
        "Written by `python -m bench.run_all` (`make bench`). "
        f"Machine: {info['cpu']}, {info['cores']} cores, Python {info['python']}, "
        f"{info['platform']}; run {info['date']}, load average at the start {info['load']}. "
        "The machine was shared with other developers' test runs, so figures are noisy: "
        "each benchmark repeats its runs and gives the best and the median."
        f"{' Quick form (--quick).' if args.quick else ''}\n\n"
    )
    findings = Path(__file__).resolve().parent / "findings.md"
    if findings.exists():  # what the figures mean, kept by hand
        sections.append(findings.read_text())
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(header + "\n".join(sections))
    print(f"wrote {args.out} in {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
