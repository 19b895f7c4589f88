"""A real scrape: Prometheus scrapes `pkwbus run`, which polls simulated drives.

The simulator runs in the test's event loop and serves the line on TCP (a
``socket://`` port, like a serial-over-TCP gateway), so the test knows the
drives' values; the service is a subprocess; Prometheus is the Debian
package's binary with a temporary config and TSDB. The test asks
Prometheus's HTTP API, not the service, so what it proves is what a
dashboard would see.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import shutil
import signal
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from pkwbus.sim import SimTiming, Simulator
from tests.deploy.conftest import DRIVES, RAMP_RAW, RAMP_SECONDS, service_config
from tests.reliability.service import start_run

# PKWBUS_PROMETHEUS: another prometheus binary than the one on PATH.
PROMETHEUS = (
    os.environ.get("PKWBUS_PROMETHEUS") or shutil.which("prometheus") or "/usr/bin/prometheus"
)
STARTUP = 25.0  # seconds for the service and Prometheus to come up and scrape

# In CI (CI=true) .ci/run installs Prometheus first: a missing binary there is a failure.
pytestmark = pytest.mark.skipif(
    not os.access(PROMETHEUS, os.X_OK) and os.environ.get("CI") != "true",
    reason=f"no prometheus binary at {PROMETHEUS}: install the Debian package prometheus"
    " (deploy/check does) or set PKWBUS_PROMETHEUS",
)


Process = asyncio.subprocess.Process
# Prometheus says where it listens once it has bound (at log level info).
LISTENING = re.compile(r'msg="Listening on" address=127\.0\.0\.1:(\d+)')


@contextlib.asynccontextmanager
async def stopped_at_exit(proc: Process) -> AsyncIterator[Process]:
    """On the way out terminate ``proc``, kill it if it hangs."""
    try:
        yield proc
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGTERM)
            try:
                await asyncio.wait_for(proc.wait(), 10)
            except TimeoutError:
                proc.kill()
                await asyncio.wait_for(proc.wait(), 10)


async def prometheus(config: Path, tsdb: Path, log: Path) -> tuple[Process, int]:
    """Prometheus on a loopback port of its own (port 0), and the port it got, from its log."""
    with log.open("wb") as out:
        proc = await asyncio.create_subprocess_exec(
            PROMETHEUS, f"--config.file={config}", f"--storage.tsdb.path={tsdb}",
            "--web.listen-address=127.0.0.1:0", "--log.level=info",
            stdout=out, stderr=asyncio.subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip
    loop = asyncio.get_running_loop()
    end = loop.time() + STARTUP
    while (found := LISTENING.search(log.read_text(errors="replace"))) is None:
        if proc.returncode is not None or loop.time() > end:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()
            pytest.fail(f"prometheus did not say where it listens:\n{log.read_text()[-3000:]}")
        await asyncio.sleep(0.1)
    return proc, int(found.group(1))


@contextlib.asynccontextmanager
async def simulator() -> AsyncIterator[tuple[Simulator, str]]:
    """The test line's drives, 3-41 set to RAMP_RAW, served on TCP: (simulator, socket:// URL)."""
    timing = SimTiming(response_delay=0.002)
    sim = Simulator("fc", DRIVES.values(), timing=timing, catalog="danfoss-fc")
    for name, address in DRIVES.items():
        sim.drives[address].set_value(341, RAMP_RAW[name])
    server = await sim.serve_tcp("127.0.0.1", 0)
    try:
        yield sim, server.url
    finally:
        await server.close()


def prometheus_config(target: str) -> str:
    return f"""\
global:
  scrape_interval: 1s
  scrape_timeout: 900ms
  evaluation_interval: 1s
scrape_configs:
  - job_name: pkwbus
    metrics_path: /metrics
    static_configs:
      - targets: ["{target}"]
"""


async def wait_for(
    what: str,
    check: Any,
    deadline: float,
    procs: list[Process],
    logs: list[Path],
) -> Any:
    """Poll the coroutine function ``check`` until it returns something truthy."""
    last: object = None
    while time.monotonic() < deadline:
        for proc, log in zip(procs, logs, strict=True):
            if proc.returncode is not None:
                pytest.fail(
                    f"{log.stem} exited with {proc.returncode} while waiting for {what}:\n"
                    + log.read_text(errors="replace")[-3000:]
                )
        try:
            result = await check()
        except httpx.HTTPError as exc:
            last = exc
        else:
            if result:
                return result
            last = result
        await asyncio.sleep(0.25)
    tails = "\n".join(f"--- {log.name}:\n{log.read_text(errors='replace')[-2000:]}" for log in logs)
    pytest.fail(f"timed out waiting for {what} (last: {last!r})\n{tails}")


async def test_prometheus_scrapes_the_service(tmp_path: Path) -> None:
    async with simulator() as (sim, port), httpx.AsyncClient(timeout=5.0) as http:
        config = tmp_path / "pkwbus.yaml"
        config.write_text(service_config(port, tmp_path))
        logs = [tmp_path / "pkwbus.log", tmp_path / "prometheus.log"]
        prom_config = tmp_path / "prometheus.yml"
        async with contextlib.AsyncExitStack() as stack:
            # Each on a port of its own: no other test worker can take it meanwhile.
            service, service_port = await start_run(["run", "--config", str(config)], logs[0])
            await stack.enter_async_context(stopped_at_exit(service))
            service_listen = f"127.0.0.1:{service_port}"
            prom_config.write_text(prometheus_config(service_listen))
            prom, prom_port = await prometheus(prom_config, tmp_path / "tsdb", logs[1])
            await stack.enter_async_context(stopped_at_exit(prom))
            prom_listen = f"127.0.0.1:{prom_port}"
            procs = [service, prom]
            deadline = time.monotonic() + STARTUP
            api = f"http://{prom_listen}/api/v1"

            async def target_up() -> dict[str, Any] | None:
                r = await http.get(f"{api}/targets", params={"state": "active"})
                r.raise_for_status()
                targets = r.json()["data"]["activeTargets"]
                return next((t for t in targets if t["health"] == "up"), None)

            target = await wait_for("the pkwbus target to be up", target_up, deadline, procs, logs)
            assert target["labels"]["job"] == "pkwbus"
            assert target["scrapeUrl"] == f"http://{service_listen}/metrics"

            async def query(expr: str) -> dict[tuple[str, str], float]:
                r = await http.get(f"{api}/query", params={"query": expr})
                r.raise_for_status()
                body = r.json()
                assert body["status"] == "success", body
                return {
                    (s["metric"].get("drive", ""), s["metric"].get("parameter", "")): float(
                        s["value"][1]
                    )
                    for s in body["data"]["result"]
                }

            async def drives_up() -> dict[tuple[str, str], float] | None:
                got = await query('pkwbus_drive_up{job="pkwbus", line="test_line"}')
                return got if {d for d, _ in got} == set(DRIVES) else None

            up = await wait_for("pkwbus_drive_up of both drives", drives_up, deadline, procs, logs)
            assert up == {(name, ""): 1.0 for name in DRIVES}

            async def ramp_values() -> dict[tuple[str, str], float] | None:
                got = await query('pkwbus_parameter_value{job="pkwbus", parameter="3-41"}')
                return got if len(got) == len(DRIVES) else None

            values = await wait_for("the values of 3-41", ramp_values, deadline, procs, logs)
            assert values == pytest.approx(
                {(name, "3-41"): seconds for name, seconds in RAMP_SECONDS.items()}
            )

            # A value changed at the drive reaches Prometheus at the next poll and scrape.
            sim.drives[DRIVES["fan_a"]].set_value(341, 4321)

            async def changed() -> bool:
                got = await query('pkwbus_parameter_value{drive="fan_a", parameter="3-41"}')
                return got.get(("fan_a", "3-41")) == pytest.approx(43.21)

            await wait_for("the changed value of 3-41", changed, time.monotonic() + 10, procs, logs)

            # The live reading is there too, and the catalog's facts of each parameter.
            freq = await query('pkwbus_parameter_value{parameter="16-13"}')
            assert set(freq) == {(name, "16-13") for name in DRIVES}
            info = await query('pkwbus_parameter_info{parameter="3-41", unit="s", pnu="341"}')
            assert set(info) == {(name, "3-41") for name in DRIVES}
