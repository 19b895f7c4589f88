"""Write latency while polls saturate the line.

Design goal: a write waits at most for the exchange in flight. A write over
the API is one exchange of its own (its old value is the latest polled one),
ahead of every poll, so the expected figure is under 2 exchange times
whatever the poll load. What is asserted is counted on the line, not timed: the
telegrams the line sent while each write's job was queued (a loaded machine slows the
service and the drives alike, not that count); the wall-clock figures are printed
(pytest -s) and measured by bench/write_latency.py.

The simulated drives answer from the test's own event loop: when a loaded machine holds
that loop, their answers stop mid-telegram with it, which no RS-485 line does (a drive's
bytes wait in the port's buffer, read before any timer of the loop fires). With the
line's 5 ms inter-character gap and 0.1 s answer timeout such a hold ended answers as
truncated, twice in a row now and then (a 504 for a write the drive had made). The line
here waits generously for them: the drives' answers are complete and in time, so the
figures are the same, and only the held loop's false gaps go.
"""

from __future__ import annotations

import asyncio
import statistics
from pathlib import Path
from typing import Any

from pkwbus.sim import SimTiming
from tests.service.http.conftest import fc_drives, service

POLLS = [(p, "10ms") for p in ("16-13", "16-14", "16-10", "16-30", "15-00", "16-90")]
WRITES = 40
# Generous for the held loop (above); FC telegrams end at their known length, not a gap.
LINE_TIMEOUT = 2.0  # seconds
INTER_CHAR_TIMEOUT = 0.5  # seconds


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


async def test_write_latency_under_saturated_polling(tmp_path: Path) -> None:
    timing = SimTiming(response_delay=0.002, baudrate=38400, wire_timing=True)
    async with service(
        tmp_path,
        fc=fc_drives(polls=POLLS),
        timing=timing,
        line_timeout=LINE_TIMEOUT,
        inter_char_timeout=INTER_CHAR_TIMEOUT,
    ) as svc:
        runtime = svc.runtime
        registry = runtime.registry
        loop = asyncio.get_running_loop()
        await asyncio.sleep(1.0)  # let the polls fill the line
        overruns_before = _sum(registry, "pkwbus_poll_overruns_total")
        busy_before = _sum(registry, "pkwbus_line_busy_seconds_total")
        started = loop.time()
        latencies = []
        telegrams: list[float] = []  # sent on the line while each write's job was queued
        submit = runtime.submit

        def counted(*args: Any, **kwargs: Any) -> asyncio.Future[Any]:
            # Counted once the job is queued: submitting records the line's events,
            # so the count includes every telegram sent before (not up to a batch of
            # them, still unrecorded, as counted before submitting).
            future = submit(*args, **kwargs)
            sent = _sum(registry, "pkwbus_telegrams_total")
            future.add_done_callback(
                lambda _: telegrams.append(_sum(registry, "pkwbus_telegrams_total") - sent)
            )
            return future

        runtime.submit = counted  # type: ignore[method-assign]
        for i in range(WRITES):
            t0 = loop.time()
            r = await svc.put(f"fan{i % 3 + 1}", "3-41", {"value": 10 + i})
            latencies.append(loop.time() - t0)
            assert r.status_code == 200, r.text
        runtime.submit = submit  # type: ignore[method-assign]
        assert len(telegrams) == WRITES  # one job each: the old value is the polled one
        elapsed = loop.time() - started
        busy = _sum(registry, "pkwbus_line_busy_seconds_total") - busy_before
        overruns = _sum(registry, "pkwbus_poll_overruns_total") - overruns_before
        count = registry.get_sample_value(
            "pkwbus_transaction_duration_seconds_count", {"line": "line_fc"}
        )
        total = registry.get_sample_value(
            "pkwbus_transaction_duration_seconds_sum", {"line": "line_fc"}
        )
        assert count and total
        exchange = total / count
        median = statistics.median(latencies)
        p99 = percentile(latencies, 0.99)
        print(
            f"\nwrite latency under saturated polling ({WRITES} writes):"
            f" exchange {exchange * 1e3:.2f} ms (mean of {count:.0f});"
            f" line busy {busy / elapsed:.0%}; poll overruns {overruns:.0f};"
            f" median {median * 1e3:.1f} ms = {median / exchange:.1f} exchanges;"
            f" p99 {p99 * 1e3:.1f} ms = {p99 / exchange:.1f} exchanges;"
            f" max {max(latencies) * 1e3:.1f} ms;"
            f" telegrams while a write was queued: median {statistics.median(telegrams):.0f},"
            f" max {max(telegrams):.0f}"
        )
        assert overruns > 0, "the polls did not saturate the line"
        assert max(telegrams) <= 10, telegrams


def _sum(registry: object, name: str) -> float:
    total = 0.0
    for metric in registry.collect():  # type: ignore[attr-defined]
        for sample in metric.samples:
            if sample.name == name:
                total += sample.value
    return total
