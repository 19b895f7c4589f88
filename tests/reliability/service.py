"""`pkwbus run` as a subprocess against a simulator served from the test's event loop."""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import sys
from pathlib import Path
from typing import Any

import httpx

from .helpers import config_text, fc_line, wait_for

TOKEN = "s3cr3t-Wr1te-T0ken-4711"
TOKEN_ENV = "PKWBUS_TEST_WRITE_TOKEN"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.audit_db = audit_db or tmp / "audit.sqlite"
        self.config = tmp / "config.yaml"
        line = fc_line("l1", url, [1], ["16-13"], every=every, timeout=timeout, retries=0)
        api = {"write_token_env": TOKEN_ENV, **(api or {})}
        self.config.write_text(config_text([line], audit_db=str(self.audit_db), api=api))
        self.log = tmp / "stderr.log"
        self.extra = list(extra)
        self.proc: asyncio.subprocess.Process | None = None

    async def start(self) -> None:
        """Start and wait until ready. The port was free when chosen; a process of
        another test worker may take it before the service binds it: then again."""
        for _ in range(5):
            if await self._start():
                return
            self.port = free_port()
            self.base = f"http://127.0.0.1:{self.port}"
        raise AssertionError(self.log.read_text())

    async def _start(self) -> bool:
        """Whether the service became ready; False when its port was taken meanwhile."""
        env = {**os.environ, TOKEN_ENV: TOKEN}
        logged = self.log.stat().st_size if self.log.exists() else 0
        with self.log.open("ab") as err:
            self.proc = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "pkwbus", *self.extra, "run", "--config", str(self.config),
                "--listen", f"127.0.0.1:{self.port}",
                stdout=asyncio.subprocess.DEVNULL, stderr=err, env=env,
            )  # fmt: skip
        async with httpx.AsyncClient(base_url=self.base) as client:

            async def ready() -> bool:
                try:
                    return (await client.get("/readyz")).status_code == 200
                except httpx.TransportError:
                    return False

            loop = asyncio.get_running_loop()
            end = loop.time() + 20

            def said() -> str:  # what this start logged
                return self.log.read_bytes()[logged:].decode(errors="replace")

            # Ready: ours (bound, so not another worker's service on the port) answers.
            while not (f"metrics on {self.base}/metrics" in said() and await ready()):
                if self.proc.returncode is not None:
                    assert "cannot listen on" in said(), said()
                    return False
                assert loop.time() < end, "the service did not become ready"
                await asyncio.sleep(0.1)
        return True

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


__all__ = ["TOKEN", "TOKEN_ENV", "Service", "wait_for"]
