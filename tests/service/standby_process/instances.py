"""`pkwbus run` instances of one hot standby group: the same configuration file, a
``standby:`` section naming the test's etcd, each with its own ``PKWBUS_INSTANCE``."""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import httpx

LISTENING = re.compile(r"metrics on http://127\.0\.0\.1:(\d+)/metrics")


def group_config(
    path: Path,
    urls: Sequence[str],
    etcd: Sequence[str],
    *,
    lease: float,
    prefix: str = "/pkwbus-test",
    every: str = "50ms",
) -> Path:
    """One line ``l{i}`` per follower url (FC drive 1, 16-13 polled ``every``), the standby
    section naming ``etcd``; written as JSON, which is YAML."""
    lines = [
        {
            "name": f"l{i}",
            "port": url,
            "protocol": "fc",
            "baudrate": 115200,
            "timeout": "250ms",
            "retries": 1,
            "alarms": "off",
            "settings": "off",
            "drives": [
                {
                    "name": f"l{i}_d1",
                    "address": 1,
                    "catalog": "danfoss-fc",
                    "poll": [{"parameter": "16-13", "every": every}],
                }
            ],
        }
        for i, url in enumerate(urls, start=1)
    ]
    body: dict[str, Any] = {
        "audit_db": "audit.sqlite",
        "standby": {"etcd": list(etcd), "lease": f"{lease:g}s", "prefix": prefix},
        "lines": lines,
    }
    path.write_text(json.dumps(body, indent=1))
    return path


class Instance:
    """One `pkwbus run --config CONFIG` named ``name``, its stderr in ``log``; it runs in a
    folder of its own beside the log (its relative files: audit, history, descriptions)."""

    def __init__(self, name: str, config: Path, log: Path) -> None:
        self.name = name
        self.folder = log.parent / name
        self.folder.mkdir(parents=True, exist_ok=True)
        self.config = config
        self.log = log
        self.proc: asyncio.subprocess.Process | None = None
        self.port = 0

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.returncode is None

    async def start(self, timeout: float = 30.0, owners: dict[int, str] | None = None) -> None:
        """Until it listens (the port the system gave it, from its own log line). Its pid goes
        into ``owners`` (a follower's) as soon as it is there, before it can connect."""
        loop = asyncio.get_running_loop()
        logged = self.log.stat().st_size if self.log.exists() else 0
        env = {**os.environ, "PKWBUS_INSTANCE": self.name}
        with self.log.open("ab") as err:
            self.proc = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "pkwbus", "run", "--config", str(self.config),
                "--listen", "127.0.0.1:0",
                stdout=asyncio.subprocess.DEVNULL, stderr=err, env=env, cwd=self.folder,
            )  # fmt: skip
        if owners is not None:
            owners[self.proc.pid] = self.name
        end = loop.time() + timeout
        while (found := LISTENING.search(said := self.said(logged))) is None:
            assert self.proc.returncode is None, f"{self.name} exited before it listened:\n{said}"
            assert loop.time() < end, f"{self.name} did not start listening:\n{said}"
            await asyncio.sleep(0.05)
        self.port = int(found.group(1))

    def said(self, since: int = 0) -> str:
        return self.log.read_bytes()[since:].decode(errors="replace") if self.log.exists() else ""

    def signal(self, sig: int) -> None:
        assert self.proc is not None
        self.proc.send_signal(sig)

    async def kill(self) -> None:
        """SIGKILL (a SIGSTOPped process too), and reap it."""
        if self.proc is not None and self.proc.returncode is None:
            self.proc.send_signal(signal.SIGKILL)
            await self.proc.wait()

    async def wait(self, timeout: float) -> int:
        assert self.proc is not None
        return await asyncio.wait_for(self.proc.wait(), timeout)

    async def metric(self, name: str, **labels: str) -> float | None:
        """The value of one series on its /metrics (None: not there, or no answer)."""
        try:
            async with httpx.AsyncClient(timeout=2) as client:
                text = (await client.get(f"http://127.0.0.1:{self.port}/metrics")).text
        except httpx.HTTPError:
            return None
        for line in text.splitlines():
            if not line.startswith(name):
                continue
            head, _, value = line.rpartition(" ")
            series = head[len(name) :]
            if series and not series.startswith("{"):
                continue
            if all(f'{k}="{v}"' in series for k, v in labels.items()):
                return float(value)
        return None
