"""Line efficiency: exchanges per second against the line's theoretical rate.

The simulated drive runs in another process on a pty with wire timing: it
answers when a real RS-485 line would deliver the last byte of its answer
(request bytes x 11 / baud + response delay + answer bytes x 11 / baud after
the request's first byte). The master runs jobs back to back on a command's
line session (the line runner; one FC parameter read after another). The
theoretical exchange time is

    request bytes x 11 / baud + start pause (3.5 characters)
    + response delay + response bytes x 11 / baud

with 16 bytes each way (FC parameter telegram).

    .venv/bin/python -m bench.line_efficiency [--seconds 5] [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from typing import Any

from bench._common import FC_TELEGRAM, best_median, exchange_time, make_port, sim_process
from bench._measure import markdown_table
from pkwbus import link
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.sessions.session import LineSession
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.protocol import pkw

BAUDRATES = (9600, 19200, 115200)
DELAY = 0.002
GOALS = {9600: 0.98, 115200: 0.95}


async def back_to_back(port: str, baudrate: int, seconds: float) -> float:
    """Completed jobs per second, one after another."""
    line = make_port(port, "fc", baudrate, timeout=0.2)
    target = DriveTarget.create("fc", 1)
    request = pkw.read(target.dialect, 1613)
    loop = asyncio.get_running_loop()
    async with LineSession(
        line, ExchangeWire(line.timeout), [DriveSpec("d", carrier_for(target))], retries=2
    ) as session:
        for _ in range(3):  # warm-up
            await session.job("d", request, loop.time() + 1)
        done = bad = 0
        start = time.perf_counter()
        while time.perf_counter() - start < seconds:
            job = await session.job("d", request, loop.time() + 1)
            if isinstance(job.outcome, Answered) and job.tally and job.tally.telegrams == 1:
                done += 1
            else:
                bad += 1
        elapsed = time.perf_counter() - start
    if bad:
        print(f"  {bad} jobs took more than one exchange at {baudrate} baud", file=sys.stderr)
    return done / elapsed


def measure(baudrate: int, seconds: float) -> float:
    with sim_process("fc", "1", response_delay=DELAY, baudrate=baudrate, wire_timing=True) as port:
        return link.run(back_to_back(port, baudrate, seconds))


def run(
    seconds: float = 5.0, repeat: int = 3, baudrates: tuple[int, ...] = BAUDRATES
) -> dict[str, Any]:
    rows = []
    for baud in baudrates:
        theory = 1.0 / exchange_time(baud, FC_TELEGRAM, FC_TELEGRAM, DELAY)
        rates = [measure(baud, seconds) for _ in range(repeat)]
        best, med = best_median(rates)
        goal = GOALS.get(baud)
        rows.append(
            {
                "baud": baud,
                "theory": theory,
                "best": best,
                "median": med,
                "ratio_best": best / theory,
                "ratio_median": med / theory,
                "goal": f"≥ {goal}" if goal else "",
                "met": ("yes" if med / theory >= goal else "no") if goal else "",
            }
        )
    table = markdown_table(
        rows,
        {
            "baud": "baud",
            "theory": "theoretical exchanges/s",
            "best": "achieved, best",
            "median": "achieved, median",
            "ratio_best": "ratio, best",
            "ratio_median": "ratio, median",
            "goal": "goal",
            "met": "met (median)",
        },
        digits=3,
    )
    return {"rows": rows, "table": table, "delay": DELAY, "seconds": seconds, "repeat": repeat}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--baud", type=int, action="append")
    args = parser.parse_args()
    result = run(args.seconds, args.repeat, tuple(args.baud or BAUDRATES))
    print(result["table"])


if __name__ == "__main__":
    main()
