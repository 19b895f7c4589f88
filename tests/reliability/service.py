"""`pkwbus run` as a subprocess against a simulator served from the test's event loop, on a
loopback port of its own (:func:`start_run`, which the other process tests use too)."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import httpx

from .helpers import config_text, fc_line, wait_for

TOKEN = "s3cr3t-Wr1te-T0ken-4711"
TOKEN_ENV = "PKWBUS_TEST_WRITE_TOKEN"


# The service's log line that names where it listens (the port the system chose).
LISTENING = re.compile(r"metrics on http://127\.0\.0\.1:(\d+)/metrics")


async def start_run(
    args: Sequence[str],
    log: Path,
    *,
    env: Mapping[str, str] | None = None,
    cwd: Path | None = None,
    timeout: float = 30.0,
) -> tuple[asyncio.subprocess.Process, int]:
    """``python -m pkwbus ARGS --listen 127.0.0.1:0`` (ARGS: ``run`` and its options), its
    stderr appended to ``log``; returns it and the port the system gave it, read back from
    its own log line once it listens (no port is picked before it binds: none to lose to
    another test worker)."""
    loop = asyncio.get_running_loop()
    logged = log.stat().st_size if log.exists() else 0
    with log.open("ab") as err:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "pkwbus", *args, "--listen", "127.0.0.1:0",
            stdout=asyncio.subprocess.DEVNULL, stderr=err, env=env, cwd=cwd,
        )  # fmt: skip
    end = loop.time() + timeout
    while (
        found := LISTENING.search(said := log.read_bytes()[logged:].decode(errors="replace"))
    ) is None:
        assert proc.returncode is None, f"pkwbus exited before it listened:\n{said}"
        assert loop.time() < end, f"pkwbus did not start listening:\n{said}"
        await asyncio.sleep(0.05)
    return proc, int(found.group(1))


class Service:
    """One `pkwbus run` process; its stderr goes to a file (``log``)."""

    def __init__(
        self,
        tmp: Path,
        url: str,
        *,
        timeout: str = "250ms",
        every: str = "30s",
        api: dict[str, Any] | None = None,
        extra: tuple[str, ...] = (),
        audit_db: Path | None = None,
    ) -> None:
        self.tmp = tmp
        self.port = 0  # known once started
        self.audit_db = audit_db or tmp / "audit.sqlite"
        self.config = tmp / "config.yaml"
        line = fc_line("l1", url, [1], ["16-13"], every=every, timeout=timeout, retries=0)
        api = {"write_token_env": TOKEN_ENV, **(api or {})}
        self.config.write_text(config_text([line], audit_db=str(self.audit_db), api=api))
        self.log = tmp / "stderr.log"
        self.extra = list(extra)
        self.proc: asyncio.subprocess.Process | None = None

    @property
    def base(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    async def start(self) -> None:
        """Start (on a port of its own, :func:`start_run`) and wait until ready."""
        env = {**os.environ, TOKEN_ENV: TOKEN}
        args = [*self.extra, "run", "--config", str(self.config)]
        self.proc, self.port = await start_run(args, self.log, env=env)
        async with httpx.AsyncClient(base_url=self.base) as client:
            loop = asyncio.get_running_loop()
            end = loop.time() + 20
            while True:
                try:
                    if (await client.get("/readyz")).status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                assert self.proc.returncode is None, self.log.read_text()
                assert loop.time() < end, "the service did not become ready"
                await asyncio.sleep(0.1)
            # Writes wait until the drive has described the parameters (AK 4): until then
            # the API answers 503 not_described.
            for parameter in ("3-41", "3-42"):
                while True:
                    r = await client.get(f"/api/v1/drives/l1_d1/parameters/{parameter}")
                    if r.status_code != 503 or r.json()["error"]["kind"] != "not_described":
                        break
                    assert loop.time() < end + 20, "the drive was not described"
                    await asyncio.sleep(0.1)

    def signal(self, sig: int) -> None:
        assert self.proc is not None
        self.proc.send_signal(sig)

    async def wait(self, timeout: float) -> int:
        assert self.proc is not None
        return await asyncio.wait_for(self.proc.wait(), timeout)

    async def stop(self) -> None:
        if self.proc is not None and self.proc.returncode is None:
            self.proc.send_signal(signal.SIGKILL)
            await self.proc.wait()

    def client(self, **kw: Any) -> httpx.AsyncClient:
        return httpx.AsyncClient(base_url=self.base, timeout=30, **kw)


__all__ = ["TOKEN", "TOKEN_ENV", "Service", "start_run", "wait_for"]
