"""Scale: 126 drives x 20 parameters on one line, and 8 such lines in one process.

Each line goes to its own simulated line (another process, pty, wire timing
at 115200 baud, 2 ms response delay, 126 FC drives). Every parameter is
polled every second, far more than a line carries, so each line runs at
full load; the measuring starts once every polled parameter has a value
(each of the twenty is one the simulated drive answers). Measured in this
process (the service: runtime from a configuration, FastAPI on uvicorn):
resident memory (VmRSS), CPU per second and per exchange, the time of the
/metrics renderer in the event loop (of ``generate_latest`` where the
service has no other), the time and size of ``GET /metrics`` from a client
in another process (one 4 s after the last on a kept-alive connection, as
Prometheus scrapes pkwbus, when some 5,000 values are new; and the median of
ten back to back), the number of parameter values in it, and the exchanges
per second while that client scrapes back to back (polling must keep its
pace).

    .venv/bin/python -m bench.scale [--lines 1 --lines 8] [--seconds 10]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import statistics
import tempfile
import time
from collections.abc import Iterator
from typing import Any

from bench._common import Service, http_client, rss_mb, service_config, sim_process
from bench._measure import markdown_table
from pkwbus import link

BAUD = 115200
# Seconds between two scrapes as the deploy's Prometheus has them (scrape_interval 5s),
# short of the service's 5 s keep-alive.
SPACED = 4.0
DELAY = 0.002
# Twenty values every simulated FC drive answers: its table's numbers (15-40, a
# text, aside) and five entries of the alarm log 15-30.
PARAMETERS = (
    "1-20", "3-41", "3-42", "4-14", "15-00", "15-02", "15-30[0]", "15-30[1]", "15-30[2]",
    "15-30[3]", "15-30[4]", "16-00", "16-03", "16-10", "16-13", "16-14", "16-30", "16-90",
    "16-92", "15-30[5]",
)  # fmt: skip


@contextlib.contextmanager
def fc_lines(lines: int, drives: int, *, own_seeds: bool = False) -> Iterator[list[str]]:
    """``lines`` simulated lines as this benchmark has them (a process each, FC drives 1 to
    ``drives`` with the Danfoss catalog, wire timing at BAUD, DELAY to answer); their ptys'
    paths. ``own_seeds``: a seed of each line's own, so that the drives' warnings and trips
    (which the service reads from their logs) come at other times on each line."""
    with contextlib.ExitStack() as stack:
        yield [
            stack.enter_context(
                sim_process(
                    "fc", f"1-{drives}", response_delay=DELAY, baudrate=BAUD, wire_timing=True,
                    catalog="danfoss-fc", extra=("--seed", str(n + 1)) if own_seeds else (),
                )
            )
            for n in range(lines)
        ]  # fmt: skip


def _telegrams(runtime: Any) -> float:
    """Telegrams exchanged on every line: the lines' plain counts, not a registry
    collect(), which would hold the event loop for a quarter of a second at 8 lines."""
    return float(sum(t.telegrams for t in runtime.snapshot.totals.values()))


async def _render(registry: Any) -> bytes:
    """The service's /metrics renderer, or generate_latest for a service without one."""
    try:
        from pkwbus.service.metrics.exposition import render
    except ImportError:
        from prometheus_client import generate_latest

        return generate_latest(registry)
    return await render(registry)


async def _measure(ports: list[str], drives: int, seconds: float) -> dict[str, Any]:

    with tempfile.TemporaryDirectory() as tmp:
        text = service_config(
            ports, drives=drives, pnus=PARAMETERS, every="1s", baudrate=BAUD,
            audit_db=f"{tmp}/audit.sqlite",
        )  # fmt: skip
        rss0 = rss_mb()
        async with Service(text, nodelay=True) as service:
            runtime = service.runtime
            polled = len(ports) * drives * len(PARAMETERS)
            # The scrape is measured with a value for every polled parameter: at full
            # load a line needs about 15 s to read each one once.
            ready = time.perf_counter() + 60.0
            while len(runtime.snapshot.readings) < polled and time.perf_counter() < ready:
                await asyncio.sleep(0.5)
            # Meanwhile, as Prometheus does with pkwbus (deploy/prometheus), a client on a
            # kept-alive connection scrapes, waits SPACED seconds, and scrapes again:
            # some 5,000 values are new by then.
            spaced = asyncio.create_task(http_client("scrape", service.base, "2", str(SPACED)))
            await asyncio.sleep(1.0)  # its first scrape (the one that makes caches) is over
            n0, c0, t0 = _telegrams(runtime), time.process_time(), time.perf_counter()
            await asyncio.sleep(seconds)
            n1, c1, t1 = _telegrams(runtime), time.process_time(), time.perf_counter()
            rss = rss_mb()
            first = await spaced
            gen = []
            size = 0
            payload = b""
            for _ in range(5):
                g0 = time.perf_counter()
                payload = await _render(runtime.registry)
                gen.append(time.perf_counter() - g0)
                size = len(payload)
                await asyncio.sleep(0.05)
            values = payload.count(b"\npkwbus_parameter_value{")
            n2, t2 = _telegrams(runtime), time.perf_counter()
            http = await http_client("scrape", service.base, "10")
            n3, t3 = _telegrams(runtime), time.perf_counter()
    http_s = statistics.median(http["latencies"])  # type: ignore[arg-type]
    first_s = float(first["latencies"][1])  # type: ignore[index]
    slowest = max(statistics.median(gen), http_s, first_s)
    return {
        "memory_met": "yes" if rss < 80 else "no",
        "scrape_met": "yes" if slowest < 0.05 else "no",
        "lines": len(ports),
        "polled": polled,
        "values": values,
        "rss_mb": rss,
        "rss_before_mb": rss0,
        "exchanges_s": (n1 - n0) / (t1 - t0),
        "scraped_exchanges_s": (n3 - n2) / (t3 - t2),
        "cpu_load": (c1 - c0) / (t1 - t0),
        "cpu_us": (c1 - c0) * 1e6 / max(1.0, n1 - n0),
        "gen_ms": statistics.median(gen) * 1e3,
        "http_ms": http_s * 1e3,
        "first_ms": first_s * 1e3,
        "size_kb": size / 1024,
    }


def measure(lines: int, drives: int, seconds: float) -> dict[str, Any]:
    with fc_lines(lines, drives) as ports:
        return link.run(_measure(ports, drives, seconds))


def run(
    lines: tuple[int, ...] = (1, 8), drives: int = 126, seconds: float = 10.0
) -> dict[str, Any]:
    rows = [measure(n, drives, seconds) for n in lines]
    table = markdown_table(
        rows,
        {
            "lines": "lines",
            "polled": "polled parameters",
            "values": "values in /metrics",
            "exchanges_s": "exchanges/s",
            "rss_mb": "VmRSS MB",
            "cpu_load": "CPU (cores)",
            "cpu_us": "CPU µs/exchange",
            "scraped_exchanges_s": "exchanges/s while scraped",
            "gen_ms": "render ms",
            "first_ms": f"GET /metrics ms, {SPACED:.0f} s after the last",
            "http_ms": "GET /metrics ms, back to back (median)",
            "size_kb": "size KiB",
            "memory_met": "< 80 MB",
            "scrape_met": "scrape < 50 ms",
        },
        digits=1,
    )
    return {"rows": rows, "table": table, "drives": drives}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--lines", type=int, action="append")
    parser.add_argument("--drives", type=int, default=126)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    print(run(tuple(args.lines or (1, 8)), args.drives, args.seconds)["table"])


if __name__ == "__main__":
    main()
