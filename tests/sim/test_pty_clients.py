"""A simulator's pty serves any number of successive clients, whatever parity they ask for."""

from __future__ import annotations

import asyncio
import contextlib
import pathlib
import signal
import subprocess
import sys
from collections.abc import Iterator

import httpx
import pytest

from tests.reliability.service import start_run

COMMAND_TIMEOUT = 60


@pytest.fixture
def pty_link(tmp_path: pathlib.Path) -> Iterator[pathlib.Path]:
    """`pkwbus simulate --pty` in its own process, FC drives 1-3 and 7."""
    link = tmp_path / "ttySIM0"
    proc = subprocess.Popen(
        [sys.executable, "-m", "pkwbus", "simulate", "--protocol", "fc", "--pty", str(link),
         "--drives", "1-3,7", "--response-delay", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    assert proc.stdout is not None
    line = proc.stdout.readline()
    assert line.startswith("simulating"), proc.stderr.read() if proc.stderr else line
    try:
        yield link
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 0


def read(link: pathlib.Path, parity: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pkwbus", "read", "--port", str(link), "--protocol", "fc",
         "--address", "7", "--parity", parity, "16-13"],
        capture_output=True,
        text=True,
        timeout=COMMAND_TIMEOUT,
    )  # fmt: skip


def test_successive_reads_with_every_parity(pty_link: pathlib.Path) -> None:
    for parity in ("E", "E", "E", "O", "O", "N", "N", "E", "O", "E"):
        done = read(pty_link, parity)
        assert (done.returncode, done.stderr) == (0, ""), parity
        assert done.stdout.startswith("16-13 = ")


async def test_a_service_brings_its_line_up_after_reads(
    pty_link: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    for parity in ("E", "E"):
        assert read(pty_link, parity).returncode == 0
    config = tmp_path / "config.yaml"
    config.write_text(
        f"""
audit_db: {tmp_path / "audit.sqlite"}
lines:
  - name: l1
    port: "{pty_link}"
    protocol: fc
    baudrate: 9600
    parity: E
    timeout: 200ms
    drives:
      - {{name: d7, address: 7, poll: [{{parameter: "16-13", every: 1s}}]}}
"""
    )
    log = tmp_path / "service.log"
    service, port = await start_run(["run", "--config", str(config)], log)
    try:
        ready = False
        loop = asyncio.get_running_loop()
        end = loop.time() + COMMAND_TIMEOUT
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}") as client:
            while not ready and loop.time() < end and service.returncode is None:
                with contextlib.suppress(httpx.TransportError):
                    ready = (await client.get("/readyz")).status_code == 200
                await asyncio.sleep(0.2)
        assert ready, log.read_text()
    finally:
        if service.returncode is None:
            service.send_signal(signal.SIGTERM)
        await asyncio.wait_for(service.wait(), COMMAND_TIMEOUT)
    done = read(pty_link, "E")
    assert (done.returncode, done.stderr) == (0, "")
