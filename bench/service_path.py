"""The service's own path, as `pkwbus run` builds it from a configuration: CPU per exchange
on an FC line, and DP cycles per second on a PROFIBUS line, beside pymodbus's async RTU
client in the same run.

Built through the configuration (``parse_config``, ``build_runtime``) only, so that the
same script measures two trees whatever their modules' layout: run it from each, in
turn, for a before/after comparison on one machine (``--tree`` names the tree in the
output).

- FC: a simulator in another process on a pty (no wire timing, no response delay), 3
  drives polling 3 parameters every 1 ms (always due: the line never idles), the
  metrics and the snapshot's collector as `pkwbus run` has them.
- DP: ``pkwbus simulate --protocol profibus`` in another process on a pty, 3 PPO 1
  slaves, each polled for 2 parameters every 1 ms through its PKW slot; cycles per
  second (Data_Exchange requests / slaves) and CPU per cycle.

    .venv/bin/python -m bench.service_path [--n 5000] [--seconds 5] [--repeat 3] [--tree NAME]
        [--without-pause]

``--without-pause`` adds the FC line with the FC/USS start pause not kept, as pymodbus
keeps none: the second wake-up per exchange that keeping it costs (see "Where the CPU per
exchange cannot go" in docs/benchmarks.md), a measurement, not a mode of the service.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from unittest import mock

from prometheus_client import CollectorRegistry

from bench._common import sim_process
from bench._measure import stop_process
from pkwbus import link
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config

BAUDRATE = 115200
FC_POLLS = ("16-13", "16-14", "16-10")
DP_ADDRESSES = (8, 9, 10)


def _fc_config(port: str) -> str:
    polls = ", ".join(f'{{parameter: "{p}", every: 1ms}}' for p in FC_POLLS)
    drives = "\n".join(
        f"      - {{name: d{a}, address: {a}, catalog: danfoss-fc, describe: off, poll: [{polls}]}}"
        for a in (1, 2, 3)
    )
    return f"""
listen: 127.0.0.1:0
audit_db: {tempfile.mkdtemp(prefix="pkwbus-bench-")}/audit.sqlite
lines:
  - name: bench
    port: {port}
    protocol: fc
    baudrate: {BAUDRATE}
    timeout: 0.5
    alarms: off
    drives:
{drives}
"""


def _dp_config(port: str) -> str:
    polls = '[{parameter: "16-13", every: 1ms}, {parameter: "16-14", every: 1ms}]'
    drives = "\n".join(
        f"      - {{name: s{a}, address: {a}, dialect: danfoss-pcv, ident: 0x0402, ppo: 1,"
        f" catalog: danfoss-fc, describe: off, poll: {polls}}}"
        for a in DP_ADDRESSES
    )
    return f"""
listen: 127.0.0.1:0
audit_db: {tempfile.mkdtemp(prefix="pkwbus-bench-")}/audit.sqlite
lines:
  - name: bench
    port: {port}
    protocol: profibus
    baudrate: 93750
    slot_time: 50ms
    alarms: off
    drives:
{drives}
"""


def _telegrams(runtime: Any) -> float:
    """The lines' telegrams so far: the snapshot's plain counts (the figures the page shows),
    not ``registry.collect()``, which costs about 0.2 ms a call (2-3 µs per exchange at 20
    calls a second) and would be counted as the service's; the registry where a tree has no
    such counts."""
    totals = getattr(getattr(runtime, "snapshot", None), "totals", None)
    if totals is not None:
        return float(sum(t.telegrams for t in totals.values()))
    return _registry_telegrams(runtime.registry)


def _registry_telegrams(registry: CollectorRegistry) -> float:
    total = 0.0
    for family in registry.collect():
        if family.name == "pkwbus_telegrams":
            total += sum(s.value for s in family.samples if s.name.endswith("_total"))
    return total


async def _measure(config_text: str, n: int | None, seconds: float | None) -> dict[str, float]:
    config = parse_config(config_text, environ={})
    runtime = await build_runtime(config)
    await runtime.start()
    try:
        loop = asyncio.get_running_loop()
        end = loop.time() + 30
        while _telegrams(runtime) < 300:
            if loop.time() > end:
                raise RuntimeError("the line did not start exchanging")
            await asyncio.sleep(0.02)
        t0, c0, w0 = _telegrams(runtime), time.process_time(), time.perf_counter()
        if n is not None:
            while _telegrams(runtime) - t0 < n:
                await asyncio.sleep(0.05)
        else:
            await asyncio.sleep(seconds or 5.0)
        t1, c1, w1 = _telegrams(runtime), time.process_time(), time.perf_counter()
    finally:
        await runtime.stop()
    count = t1 - t0
    return {"cpu_us": (c1 - c0) / count * 1e6, "rate": count / (w1 - w0), "count": count}


def fc(n: int, *, pause: bool = True) -> dict[str, float]:
    """CPU per exchange of the FC line; ``pause`` False: with the start pause not kept
    (``Link.pause_left`` patched to 0 in this process, as pymodbus writes its next request
    at once): what keeping it costs, a measurement, not a mode of the service."""
    with sim_process("fc", "1-3") as port:
        if pause:
            return link.run(_measure(_fc_config(port), n, None))
        from pkwbus.link.port import Link  # here: an older tree may lay its modules out otherwise

        with mock.patch.object(Link, "pause_left", lambda self, now: 0.0):
            return link.run(_measure(_fc_config(port), n, None))


@contextlib.contextmanager
def dp_simulator() -> Iterator[str]:
    """``pkwbus simulate --protocol profibus`` in another process: its pty's path."""
    folder = Path(tempfile.mkdtemp(prefix="pkwbus-bench-dp-"))
    pty = folder / "ttyDP"
    addresses = ",".join(str(a) for a in DP_ADDRESSES)
    proc = subprocess.Popen(
        [sys.executable, "-m", "pkwbus", "simulate", "--protocol", "profibus", "--pty", str(pty),
         "--drives", addresses, "--dialect", "danfoss-pcv", "--ppo", "1"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )  # fmt: skip
    try:
        end = time.monotonic() + 20
        while not pty.exists():
            if time.monotonic() > end or proc.poll() is not None:
                raise RuntimeError("the DP simulator did not start")
            time.sleep(0.05)
        yield str(pty)
    finally:
        stop_process(proc)


def dp(seconds: float) -> dict[str, float]:
    with dp_simulator() as pty:
        found = link.run(_measure(_dp_config(pty), None, seconds))
    cycles = found["rate"] / len(DP_ADDRESSES)
    return {"cycles_per_s": cycles, "cpu_us_per_cycle": found["cpu_us"] * len(DP_ADDRESSES)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=5000)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--tree", default="this tree")
    parser.add_argument("--no-pymodbus", action="store_true")
    parser.add_argument(
        "--without-pause",
        action="store_true",
        help="also the FC line with the start pause not kept (what it costs)",
    )
    args = parser.parse_args()
    rows: dict[str, list[float]] = {"fc": [], "fc_without_pause": [], "dp_cycles": [],
                                    "dp_cpu": [], "pymodbus": []}  # fmt: skip
    for _ in range(args.repeat):
        rows["fc"].append(fc(args.n)["cpu_us"])
        if args.without_pause:
            rows["fc_without_pause"].append(fc(args.n, pause=False)["cpu_us"])
        found = dp(args.seconds)
        rows["dp_cycles"].append(found["cycles_per_s"])
        rows["dp_cpu"].append(found["cpu_us_per_cycle"])
        if not args.no_pymodbus:
            from bench import pymodbus_baseline

            rows["pymodbus"].append(pymodbus_baseline.measure(args.n)["cpu_us_per_op"])
    out: dict[str, Any] = {"tree": args.tree}
    for key, values in rows.items():
        if values:
            out[key] = {"min": min(values), "median": statistics.median(values),
                        "max": max(values), "runs": [round(v, 1) for v in values]}  # fmt: skip
    if rows["pymodbus"]:
        pymodbus = statistics.median(rows["pymodbus"])
        out["fc_vs_pymodbus_median"] = statistics.median(rows["fc"]) / pymodbus
        if rows["fc_without_pause"]:
            out["fc_without_pause_vs_pymodbus_median"] = (
                statistics.median(rows["fc_without_pause"]) / pymodbus
            )
    for key, value in out.items():
        print(f"{key}: {value}")


if __name__ == "__main__":
    main()
