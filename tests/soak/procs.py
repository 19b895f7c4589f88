"""The soak's two processes: the simulated lines (sims.py) and ``pkwbus run``."""

from __future__ import annotations

import asyncio
import ctypes
import json
import os
import re
import signal
import sys
from pathlib import Path
from typing import Any

import httpx

__all__ = ["LISTENING", "TOKEN", "TOKEN_ENV", "start_service", "start_sims", "stop"]

TOKEN = "soak-Wr1te-T0ken-0815"
TOKEN_ENV = "PKWBUS_SOAK_WRITE_TOKEN"
READY_WITHIN = 60.0  # seconds for a process to say it is ready (a loaded machine)
PR_SET_PDEATHSIG = 1  # prctl(2)


def _end_with_the_soak() -> None:
    """In the child, before it runs: SIGTERM when the soak's process ends, however it
    ends (killed too), so that no simulator or service outlives it and takes the ptys
    and ports of the next run (Linux prctl PR_SET_PDEATHSIG)."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


# The service's log line naming where it listens: the port the system gave --listen ...:0.
LISTENING = re.compile(r"metrics on (http://127\.0\.0\.1:\d+)/metrics")


async def start_sims(folder: Path, argv: list[str]) -> tuple[asyncio.subprocess.Process, Any]:
    """The simulated lines; their first line of output (the ports and the control URL)."""
    with (folder / "sims.log").open("ab") as err:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "tests.soak.sims", "--folder", str(folder), *argv,
            stdout=asyncio.subprocess.PIPE, stderr=err, cwd=Path(__file__).parents[2],
            preexec_fn=_end_with_the_soak,
        )  # fmt: skip
    assert proc.stdout is not None
    line = await asyncio.wait_for(proc.stdout.readline(), READY_WITHIN)
    if not line:
        raise RuntimeError(f"the simulators ended: {(folder / 'sims.log').read_text()}")
    return proc, json.loads(line)


async def start_service(config: Path, log: Path) -> tuple[asyncio.subprocess.Process, str]:
    """``pkwbus run`` on a port the system gives it (read back from its log), ready to
    answer; no port is chosen before the bind, so none can be taken meanwhile."""
    logged = log.stat().st_size if log.exists() else 0
    with log.open("ab") as err:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "pkwbus", "run", "--config", str(config),
            "--listen", "127.0.0.1:0",
            stdout=asyncio.subprocess.DEVNULL, stderr=err,
            env={**os.environ, TOKEN_ENV: TOKEN}, preexec_fn=_end_with_the_soak,
        )  # fmt: skip
    try:
        return await _ready(proc, log, logged)
    except BaseException:
        await stop(proc)
        raise


async def _ready(
    proc: asyncio.subprocess.Process, log: Path, logged: int
) -> tuple[asyncio.subprocess.Process, str]:
    loop = asyncio.get_running_loop()
    end = loop.time() + READY_WITHIN
    while True:
        said = log.read_bytes()[logged:].decode(errors="replace")
        if proc.returncode is not None:
            raise RuntimeError(f"pkwbus run ended with {proc.returncode}: {said}")
        found = LISTENING.search(said)
        if found is not None:
            async with httpx.AsyncClient(base_url=found.group(1), timeout=5) as client:
                try:
                    if (await client.get("/healthz")).status_code == 200:
                        return proc, found.group(1)
                except httpx.TransportError:
                    pass
        if loop.time() > end:
            raise RuntimeError(f"pkwbus run was not ready within {READY_WITHIN} s: {said}")
        await asyncio.sleep(0.1)


async def stop(proc: asyncio.subprocess.Process, timeout: float = 60.0) -> int:
    """SIGTERM, and the exit code; killed (and -9) when it does not end in ``timeout``."""
    if proc.returncode is None:
        proc.send_signal(signal.SIGTERM)
    try:
        return await asyncio.wait_for(proc.wait(), timeout)
    except TimeoutError:
        proc.kill()
        await proc.wait()
        return -9
