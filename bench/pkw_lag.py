"""PKW lag: completed jobs/s over 4 USS drives that answer a parameter request late.

Each simulated drive (another process, pty, wire timing at 115200 baud,
2 ms response delay) answers a PKW request only after ``lag_telegrams``
further telegrams to it, or after a time, meanwhile with AK 0. Compared:
the ``LineRunner`` interleaving the 4 drives (polls always due), and
strictly sequential handling (a command's line session: one job after
another, drive after drive).

    .venv/bin/python -m bench.pkw_lag [--seconds 5] [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import time
from typing import Any

from bench._common import Counting, best_median, fc_drive, make_port, sim_process
from bench._measure import markdown_table
from pkwbus import link
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.runner import LineRunner
from pkwbus.master.sessions.session import LineSession
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.protocol import pkw

BAUD = 115200
DELAY = 0.002
PNUS = (21, 27)
LAGS = {"lag_telegrams=3": "3", "lag 20 ms": "20ms"}


async def interleaved(port: str, seconds: float) -> float:
    events = Counting()
    drives = [fc_drive(f"d{a}", a, PNUS, 0.0, "uss") for a in (1, 2, 3, 4)]
    line = make_port(port, "uss", BAUD, timeout=0.1)
    sched = LineRunner(
        "bench", line, ExchangeWire(line.timeout), drives, observers=[events],
        poll_deadline=2.0,
    )  # fmt: skip
    task = asyncio.create_task(sched.run())
    await asyncio.sleep(0.5)
    n0, t0 = events.total(), time.perf_counter()
    await asyncio.sleep(seconds)
    rate = (events.total() - n0) / (time.perf_counter() - t0)
    sched.stop()
    await task
    return rate


async def sequential(port: str, seconds: float) -> float:
    line = make_port(port, "uss", BAUD, timeout=0.1)
    targets = [DriveTarget.create("uss", a) for a in (1, 2, 3, 4)]
    specs = [DriveSpec(str(t.address), carrier_for(t)) for t in targets]
    loop = asyncio.get_running_loop()
    done = 0
    async with LineSession(line, ExchangeWire(line.timeout), specs, retries=2) as session:
        start = time.perf_counter()
        i = 0
        while time.perf_counter() - start < seconds:
            target = targets[i % 4]
            req = pkw.read(target.dialect, PNUS[(i // 4) % len(PNUS)])
            result = await session.job(str(target.address), req, loop.time() + 2.0)
            if isinstance(result.outcome, Answered):
                done += 1
            i += 1
        rate = done / (time.perf_counter() - start)
    return rate


def measure(mode: str, lag: str, seconds: float) -> float:
    with sim_process(
        "uss", "1-4", response_delay=DELAY, baudrate=BAUD, wire_timing=True, lag=lag
    ) as port:
        f = interleaved if mode == "interleaved" else sequential
        return link.run(f(port, seconds))


def run(
    seconds: float = 5.0, repeat: int = 3, lags: dict[str, str] | None = None
) -> dict[str, Any]:
    rows = []
    for name, lag in (lags or LAGS).items():
        seq = [measure("sequential", lag, seconds) for _ in range(repeat)]
        inter = [measure("interleaved", lag, seconds) for _ in range(repeat)]
        sb, sm = best_median(seq)
        ib, im = best_median(inter)
        rows.append(
            {
                "lag": name,
                "seq_best": sb,
                "seq_median": sm,
                "int_best": ib,
                "int_median": im,
                "ratio": im / sm,
            }
        )
    table = markdown_table(
        rows,
        {
            "lag": "lag",
            "seq_best": "sequential jobs/s, best",
            "seq_median": "median",
            "int_best": "interleaved jobs/s, best",
            "int_median": "median",
            "ratio": "interleaved / sequential (median)",
        },
        digits=1,
    )
    return {"rows": rows, "table": table}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(run(args.seconds, args.repeat)["table"])


if __name__ == "__main__":
    main()
