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
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from pkwbus.sim import SimTiming, Simulator
from tests.deploy.conftest import DRIVES, RAMP_RAW, RAMP_SECONDS, free_port, service_config

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


@contextlib.contextmanager
def process(args: list[str], log: Path) -> Iterator[subprocess.Popen[bytes]]:
    """Run ``args`` with output to ``log``; on the way out terminate it, kill it if it hangs."""
    with log.open("wb") as out:
        proc = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)


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
    procs: list[subprocess.Popen[bytes]],
    logs: list[Path],
) -> Any:
    """Poll the coroutine function ``check`` until it returns something truthy."""
    last: object = None
    while time.monotonic() < deadline:
        for proc, log in zip(procs, logs, strict=True):
            if proc.poll() is not None:
                pytest.fail(
                    f"{proc.args[0]} exited with {proc.returncode} while waiting for {what}:\n"
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
        service_listen = f"127.0.0.1:{free_port()}"
        prom_listen = f"127.0.0.1:{free_port()}"
        prom_config = tmp_path / "prometheus.yml"
        prom_config.write_text(prometheus_config(service_listen))
        logs = [tmp_path / "pkwbus.log", tmp_path / "prometheus.log"]
        service_args = [sys.executable, "-m", "pkwbus", "run", "--config", str(config)]
        prom_args = [
            PROMETHEUS,
            f"--config.file={prom_config}",
            f"--storage.tsdb.path={tmp_path / 'tsdb'}",
            f"--web.listen-address={prom_listen}",
            "--log.level=warn",
        ]
        with (
            process([*service_args, "--listen", service_listen], logs[0]) as service,
            process(prom_args, logs[1]) as prom,
        ):
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
