"""PROFIBUS DP: parameters per second per slave through data record 47 against PKW in a PPO.

Three simulated SINAMICS slaves on a pty with wire timing (every request and
answer takes its 11 bits a character at the baud rate; each slave answers
after min TSDR), 20 parameters polled on each, always due. The whole service
path runs: ``build_runtime`` from a configuration, the line runner, the
planner, the metrics. Counted: the polls completed per slave and second.

- **pkw**: PPO 1, one parameter per PKW job, a job at best every other cycle.
- **ds47**: PPO 3 (no PKW words), DP-V1, the due polls of a slave in one data
  record 47 request, written in one cycle and read back in the next; the
  simulated slave has its response ready at the first read.
- **ds47, PPO 1**: the same slaves' PPO 1 with data record 47, for a like-for-like
  cycle.

    python -m bench.ds47 [--seconds 5] [--baudrates 19200,93750]
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
from pathlib import Path
from typing import Any

from prometheus_client import generate_latest

from pkwbus.link import new_event_loop
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.service.config.line_load import line_load
from pkwbus.sim import SimTiming
from pkwbus.sim.profibus.line import DpSimulator

ADDRESSES = (8, 9, 10)
# The 20 numeric, non-array parameters of the simulated SINAMICS drive.
PNUS = (21, 24, 25, 26, 27, 32, 39, 52, 304, 1082, 1120, 1121, 2000, 31, 35, 1080, 305, 307,
        310, 311)  # fmt: skip
KINDS = {"pkw": (1, "pkw"), "ds47": (3, "ds47"), "ds47, PPO 1": (1, "ds47")}


def _config(port: str, baudrate: int, ppo: int, access: str, audit: Path) -> str:
    polls = ", ".join(f'{{parameter: "{p}", every: 10ms}}' for p in PNUS)
    drives = "\n".join(
        f"""      - {{name: d{a}, address: {a}, dialect: profidrive, ident: 0x80B5, ppo: {ppo},
          dpv1: true, parameter_access: {access}, catalog: siemens-g120, describe: "off",
          poll: [{polls}]}}"""
        for a in ADDRESSES
    )
    return f"""
audit_db: {audit}
lines:
  - name: dp
    port: {port}
    protocol: profibus
    baudrate: {baudrate}
    watchdog: 5s
    drives:
{drives}
"""


def _reads(runtime: Any) -> dict[str, float]:
    out: dict[str, float] = {}
    for line in generate_latest(runtime.registry).decode().splitlines():
        if line.startswith("pkwbus_jobs_total{") and 'kind="read"' in line and '"ok"' in line:
            drive = line.split('drive="', 1)[1].split('"', 1)[0]
            out[drive] = float(line.rsplit(" ", 1)[1])
    return out


async def measure(baudrate: int, kind: str, seconds: float) -> tuple[float, float]:
    """Polls completed per slave and second (the mean of the three slaves), and what
    ``check-config`` estimates at most."""
    ppo, access = KINDS[kind]
    delay = dp_timing.bits(dp_timing.MIN_TSDR_BITS, baudrate)
    timing = SimTiming(response_delay=delay, baudrate=baudrate, wire_timing=True)
    sim = DpSimulator(ADDRESSES, dialect="profidrive", ppo_number=ppo, timing=timing, seed=1,
                      catalog="siemens-g120", dpv1=True)  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        end = await sim.serve_pty(str(Path(tmp) / "ttyDP"))
        config = parse_config(
            _config(end.path, baudrate, ppo, access, Path(tmp) / "audit.sqlite"), environ={}
        )
        estimate = line_load(config.lines[0]).access["d8"][1]
        runtime = await build_runtime(config)
        await runtime.start()
        loop = asyncio.get_running_loop()
        try:
            names = [f"d{a}" for a in ADDRESSES]
            while any(_reads(runtime).get(n, 0) < len(PNUS) for n in names):  # all under way
                await asyncio.sleep(0.05)
            before, start = _reads(runtime), loop.time()
            await asyncio.sleep(seconds)
            after, elapsed = _reads(runtime), loop.time() - start
        finally:
            await runtime.stop()
            await end.close()
    per_slave = [(after[d] - before[d]) / elapsed for d in after]
    return sum(per_slave) / len(per_slave), estimate


def run(seconds: float = 5.0, baudrates: tuple[int, ...] = (19200, 93750)) -> dict[str, Any]:
    loop = new_event_loop()
    rows = []
    try:
        for baudrate in baudrates:
            got = {k: loop.run_until_complete(measure(baudrate, k, seconds)) for k in KINDS}
            rows.append((baudrate, got))
    finally:
        loop.close()
    lines = [
        "| baud | PKW in PPO 1, parameters/s per slave (check-config: at most)"
        " | data record 47, PPO 3 (at most) | ratio | data record 47, PPO 1 (at most) | ratio |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for baudrate, got in rows:
        (pkw, pkw_most), (ds, ds_most), (ds1, ds1_most) = (got[k] for k in KINDS)
        lines.append(
            f"| {baudrate} | {pkw:.1f} ({pkw_most:.1f}) | {ds:.1f} ({ds_most:.1f})"
            f" | {ds / pkw:.1f}x | {ds1:.1f} ({ds1_most:.1f}) | {ds1 / pkw:.1f}x |"
        )
    return {"rows": rows, "table": "\n".join(lines)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--baudrates", default="19200,93750")
    args = parser.parse_args()
    print(run(args.seconds, tuple(int(b) for b in args.baudrates.split(",")))["table"])


if __name__ == "__main__":
    main()
