"""Write latency: HTTP PUT to answer while polls saturate the line.

The service (runtime built from a configuration by ``build_runtime``, the
FastAPI app served by uvicorn on loopback, in this process) runs one FC line
to a simulated line in another process (pty, wire timing, 2 ms response
delay) with 3 drives whose polls are always due (every 1 ms: more than the
line carries). A client in another process (httpx) PUTs 3-41 on one drive
at random intervals and times each request until its answer. The service
answers a PUT after an audit row, a read of the old value, the write job
and two audit updates; for the master's share alone, the same number of
write jobs also goes straight to ``Runtime.submit``. Latency is reported in
units of one theoretical exchange time.

``pkwbus.service.assembly.serve.bind`` creates its socket with protocol 0, so asyncio
does not set TCP_NODELAY on the connections and every answer whose body
goes out after its headers waits for the client's delayed ACK (40 ms on
Linux). The PUT is therefore measured twice: on ``bind``'s socket, and on a
socket made with ``IPPROTO_TCP`` (the one-line fix).

    .venv/bin/python -m bench.write_latency [--writes 100] [--baud 19200]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import statistics
import tempfile
import time
from typing import Any

from bench._common import (
    FC_TELEGRAM,
    Service,
    exchange_time,
    http_client,
    service_config,
    sim_process,
)
from bench._measure import markdown_table
from pkwbus import link

DELAY = 0.002
TOKEN_ENV = "PKWBUS_BENCH_TOKEN"
TOKEN = "bench-token"
BAUDRATES = (19200, 115200)
POLLS = ("16-13", "16-14", "16-10")


async def _serve(port: str, baud: int, writes: int, gap: float, nodelay: bool) -> dict[str, Any]:
    os.environ[TOKEN_ENV] = TOKEN
    with tempfile.TemporaryDirectory() as tmp:
        text = service_config(
            [port], drives=3, pnus=POLLS, every="1ms", baudrate=baud,
            token_env=TOKEN_ENV, audit_db=f"{tmp}/audit.sqlite",
        )  # fmt: skip
        async with Service(text, nodelay=nodelay) as service:
            await asyncio.sleep(1.0)
            runtime = service.runtime
            busy0, t0 = _busy(runtime), time.perf_counter()
            http = await http_client(
                "put", service.base, "/api/v1/drives/l0d2/parameters/3-41", str(writes),
                str(gap), TOKEN,
            )  # fmt: skip
            busy = (_busy(runtime) - busy0) / (time.perf_counter() - t0)
            direct = await _direct(runtime, writes, gap)
    return {"http": http, "direct": direct, "busy": busy}


async def _direct(runtime: Any, writes: int, gap: float) -> list[float]:
    """Write jobs submitted straight to the runtime: the master's share of the latency."""
    from pkwbus.catalog.description import ParameterDescription
    from pkwbus.master.planning.jobs import JobKind
    from pkwbus.protocol import pkw

    entry = runtime.drives["l0d2"]
    rng = random.Random(2)
    out = []
    for i in range(writes):
        await asyncio.sleep(gap * (0.5 + rng.random()))
        req = pkw.write(entry.target.dialect, 341, 100 + i % 50, pkw.Width.DWORD)
        t0 = time.perf_counter()
        await runtime.submit("l0d2", req, JobKind.WRITE, ParameterDescription())
        out.append(time.perf_counter() - t0)
    return out


def _busy(runtime: Any) -> float:
    return float(runtime.snapshot.totals["line0"].busy)


def _row(path: str, baud: int, latencies: list[float], errors: int, busy: float) -> dict[str, Any]:
    unit = exchange_time(baud, FC_TELEGRAM, FC_TELEGRAM, DELAY)
    latencies = sorted(latencies)
    p99 = (
        latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))]
        if latencies
        else float("nan")
    )
    med = statistics.median(latencies) if latencies else float("nan")
    return {
        "path": path,
        "baud": baud,
        "exchange_ms": unit * 1e3,
        "writes": len(latencies),
        "errors": errors,
        "median_ms": med * 1e3,
        "p99_ms": p99 * 1e3,
        "median_x": med / unit,
        "p99_x": p99 / unit,
        "busy": busy,
        "met": "yes" if p99 / unit < 3 else "no",
    }


def measure(baud: int, writes: int, gap: float) -> list[dict[str, Any]]:
    with sim_process("fc", "1-3", response_delay=DELAY, baudrate=baud, wire_timing=True) as port:
        got = link.run(_serve(port, baud, writes, gap, nodelay=False))
    with sim_process("fc", "1-3", response_delay=DELAY, baudrate=baud, wire_timing=True) as port:
        fixed = link.run(_serve(port, baud, writes, gap, nodelay=True))
    http: dict[str, Any] = got["http"]
    http2: dict[str, Any] = fixed["http"]
    return [
        _row("HTTP PUT, app.bind socket (Nagle on)", baud, http["latencies"],
             len(http["errors"]), got["busy"]),
        _row("HTTP PUT, TCP_NODELAY socket", baud, http2["latencies"],
             len(http2["errors"]), fixed["busy"]),
        _row("write job via Runtime.submit", baud, got["direct"] + fixed["direct"], 0,
             got["busy"]),
    ]  # fmt: skip


def run(
    writes: int = 100, baudrates: tuple[int, ...] = BAUDRATES, gap: float | None = None
) -> dict[str, Any]:
    rows = []
    for baud in baudrates:
        unit = exchange_time(baud, FC_TELEGRAM, FC_TELEGRAM, DELAY)
        rows += measure(baud, writes, gap if gap is not None else max(0.02, 4 * unit))
    table = markdown_table(
        rows,
        {
            "path": "path",
            "baud": "baud",
            "exchange_ms": "1 exchange (ms)",
            "writes": "writes",
            "errors": "errors",
            "median_ms": "median ms",
            "p99_ms": "p99 ms",
            "median_x": "median (exchanges)",
            "p99_x": "p99 (exchanges)",
            "busy": "line busy",
            "met": "p99 < 3",
        },
        digits=2,
    )
    return {"rows": rows, "table": table}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--writes", type=int, default=100)
    parser.add_argument("--baud", type=int, action="append")
    args = parser.parse_args()
    print(run(args.writes, tuple(args.baud or BAUDRATES))["table"])


if __name__ == "__main__":
    main()
