"""Connection flood: `pkwbus run` under thousands of HTTP connections, polling measured.

The service runs as `pkwbus run` in its own process on a simulated line
(another process, pty, 115200 baud with wire timing, 2 ms response delay,
4 FC drives with 2 parameters each polled every 10 ms, far more than the
line carries: it runs at full load). Polls per second are taken from its /metrics over a connection
opened before the flood (kept alive, so it holds its place), first for a
quiet window, then while another process opens IDLE connections that send
nothing and PARALLEL connections that each send a GET at once. The service
must stay up, refuse what is beyond ``api.max_connections`` and keep
polling at the same rate.

    .venv/bin/python -m bench.connection_flood [--idle 5000] [--parallel 2000] [--seconds 5]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from bench._common import pkwbus_run, service_config, sim_process, telegrams_in
from bench._measure import ROOT, markdown_table, module_command


def telegrams(client: httpx.Client) -> float:
    return telegrams_in(client.get("/metrics").text)


def rate(client: httpx.Client, seconds: float) -> float:
    t0, n0 = time.monotonic(), telegrams(client)
    time.sleep(seconds)
    return (telegrams(client) - n0) / (time.monotonic() - t0)


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def run(idle: int = 5000, parallel: int = 2000, seconds: float = 5.0) -> dict[str, Any]:
    with sim_process("fc", "1-4", response_delay=0.002, baudrate=115200, wire_timing=True) as tty:
        folder = Path(tempfile.mkdtemp(prefix="pkwbus-bench-flood-"))
        config = service_config(
            [tty], drives=4, pnus=["16-13", "16-14"], every="10ms", baudrate=115200,
            audit_db=str(folder / "audit.sqlite"),
        )  # fmt: skip
        with (
            pkwbus_run(config, folder) as service,
            httpx.Client(base_url=service.base, timeout=30) as client,
        ):
            deadline = time.monotonic() + 30
            while True:
                try:
                    if client.get("/readyz").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline or service.process.poll() is not None:
                    raise RuntimeError("the service did not start")
                time.sleep(0.2)
            rate(client, 1.0)  # warm-up
            quiet = rate(client, seconds)
            flood = subprocess.Popen(
                module_command("_flood_client", "127.0.0.1", str(service.port), str(idle),
                               str(parallel), str(seconds + 2)),
                cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            )  # fmt: skip
            time.sleep(1.0)
            during = rate(client, seconds)
            out, err = flood.communicate(timeout=300)
            if flood.returncode:
                raise RuntimeError(f"the flood client failed: {err.decode()[-2000:]}")
            result = json.loads(out)
            alive = service.process.poll() is None
            after = rate(client, 2.0) if alive else 0.0
            memory = rss_mb(service.process.pid) if alive else 0.0
        text = service.log.read_text(errors="replace")
    refusals = [line for line in text.splitlines() if "refused" in line and "HTTP" in line]
    return {
        "idle": idle,
        "parallel": parallel,
        "quiet_polls_per_s": quiet,
        "flood_polls_per_s": during,
        "after_polls_per_s": after,
        "ratio": during / quiet if quiet else 0.0,
        "alive": alive,
        "rss_mb": memory,
        "refusal_log_lines": len(refusals),
        "tracebacks": text.count("Traceback"),
        "idle_opened": result["idle_opened"],
        "idle_closed_at_once": result["idle_closed_at_once"],
        "idle_connect_failed": result["idle_connect_failed"],
        "parallel_answers": result["parallel"],
    }


def table(r: dict[str, Any]) -> str:
    row = {
        "flood": f"{r['idle']} idle + {r['parallel']} parallel",
        "quiet": r["quiet_polls_per_s"],
        "during": r["flood_polls_per_s"],
        "ratio": r["ratio"],
        "alive": "yes" if r["alive"] else "NO",
        "rss": r["rss_mb"],
    }
    return markdown_table([row], {
        "flood": "Flood", "quiet": "polls/s quiet", "during": "polls/s during flood",
        "ratio": "during / quiet", "alive": "service alive", "rss": "RSS MB after",
    }, digits=2)  # fmt: skip


def measure(idle: int, parallel: int, seconds: float) -> dict[str, Any]:
    """One flood, with its table (for run_all)."""
    r = run(idle, parallel, seconds)
    return {**r, "table": table(r)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--idle", type=int, default=5000)
    parser.add_argument("--parallel", type=int, default=2000)
    parser.add_argument("--seconds", type=float, default=5.0)
    args = parser.parse_args()
    r = run(args.idle, args.parallel, args.seconds)
    print(table(r))
    print(json.dumps(r, indent=1))


if __name__ == "__main__":
    main()
