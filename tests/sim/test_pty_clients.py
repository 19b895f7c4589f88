"""A simulator's pty serves any number of successive clients, whatever parity they ask for."""

from __future__ import annotations

import contextlib
import pathlib
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator

import httpx
import pytest

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


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_service_brings_its_line_up_after_reads(
    pty_link: pathlib.Path, tmp_path: pathlib.Path
) -> None:
    for parity in ("E", "E"):
        assert read(pty_link, parity).returncode == 0
    port = free_port()
    config = tmp_path / "config.yaml"
    config.write_text(
        f"""
listen: 127.0.0.1:{port}
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
    with log.open("wb") as err:
        service = subprocess.Popen(
            [sys.executable, "-m", "pkwbus", "run", "--config", str(config)],
            stdout=subprocess.DEVNULL,
            stderr=err,
        )
    try:
        ready = False
        end = time.monotonic() + COMMAND_TIMEOUT
        while not ready and time.monotonic() < end and service.poll() is None:
            with contextlib.suppress(httpx.TransportError):
                ready = httpx.get(f"http://127.0.0.1:{port}/readyz").status_code == 200
            time.sleep(0.2)
        assert ready, log.read_text()
    finally:
        service.send_signal(signal.SIGTERM)
        service.wait(timeout=COMMAND_TIMEOUT)
    done = read(pty_link, "E")
    assert (done.returncode, done.stderr) == (0, "")
