"""Dead-drive cost: completed polls of 3 healthy drives with 0 or 1 of 4 dead, or one flapping.

The simulated line (another process, pty, wire timing at 115200 baud,
2 ms response delay) has 4 FC drives. Each polls 3 parameters every 100 ms:
90 polls/s for the healthy three, 120 in all: about two thirds of what the line
carries, so the healthy drives' polls all fit unless the dead one eats the
line. Cases: all 4 answer; drive 4 dead from the start; drive 4 dies and
revives every 2 s (flapping). The figure is completed polls per second of
drives 1-3; the ratio is against the all-healthy case.

    .venv/bin/python -m bench.dead_drive [--seconds 10] [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import time
from typing import Any

from bench._common import Counting, best_median, fc_drive, make_port, sim_process
from bench._measure import markdown_table
from pkwbus import link
from pkwbus.master.runner import LineRunner
from pkwbus.master.wires.serial.wire import ExchangeWire

BAUD = 115200
DELAY = 0.002
EVERY = 0.1
PNUS = (1613, 1614, 1610)
HEALTHY = ["d1", "d2", "d3"]
CASES = {
    "all 4 answer": {},
    "drive 4 dead": {"dead": "4"},
    "drive 4 flapping (2 s)": {"flap": "4", "flap_period": 2.0},
}


async def polls(port: str, seconds: float) -> float:
    events = Counting()
    drives = [fc_drive(f"d{a}", a, PNUS, EVERY) for a in (1, 2, 3, 4)]
    line = make_port(port, "fc", BAUD, timeout=0.1)
    sched = LineRunner("bench", line, ExchangeWire(line.timeout), drives, observers=[events])
    task = asyncio.create_task(sched.run())
    await asyncio.sleep(0.5)
    n0, t0 = events.total(HEALTHY), time.perf_counter()
    await asyncio.sleep(seconds)
    rate = (events.total(HEALTHY) - n0) / (time.perf_counter() - t0)
    sched.stop()
    await task
    return rate


def measure(case: str, seconds: float) -> float:
    kw: dict[str, Any] = dict(CASES[case])
    with sim_process(
        "fc", "1-4", response_delay=DELAY, baudrate=BAUD, wire_timing=True, **kw
    ) as port:
        return link.run(polls(port, seconds))


def run(seconds: float = 10.0, repeat: int = 3) -> dict[str, Any]:
    results = {case: [measure(case, seconds) for _ in range(repeat)] for case in CASES}
    demand = len(HEALTHY) * len(PNUS) / EVERY
    _, healthy = best_median(results["all 4 answer"])
    rows = []
    for case, rates in results.items():
        best, med = best_median(rates)
        rows.append(
            {
                "case": case,
                "best": best,
                "median": med,
                "ratio": med / healthy,
                "met": "yes" if med / healthy >= 0.95 else "no",
            }
        )
    table = markdown_table(
        rows,
        {
            "case": "case",
            "best": "healthy drives' polls/s, best",
            "median": "median",
            "ratio": "median / all-healthy median",
            "met": "≥ 0.95",
        },
        digits=2,
    )
    return {"rows": rows, "table": table, "demand": demand, "seconds": seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    result = run(args.seconds, args.repeat)
    print(f"demand {result['demand']:.0f} polls/s of the healthy drives")
    print(result["table"])


if __name__ == "__main__":
    main()
