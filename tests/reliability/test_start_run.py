"""The process tests' start of `pkwbus run`: a port another process takes between its
choice and the service's bind is given up for another, and the start returns only once
the service listens on its own."""

from __future__ import annotations

import asyncio
import signal
import socket
from pathlib import Path

import httpx
import pytest

from . import service
from .service import start_run

CONFIG = (
    "lines:\n"
    "  - name: l1\n    port: sim://fc?drives=1\n    protocol: fc\n    baudrate: 19200\n"
    "    drives: [{name: a, address: 1, poll: [{parameter: '16-13', every: 1s}]}]\n"
)


async def test_a_port_taken_before_the_bind_is_given_up_for_another(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = tmp_path / "c.yaml"
    config.write_text(f"audit_db: {tmp_path / 'audit.sqlite'}\n{CONFIG}")
    log = tmp_path / "stderr.log"
    with socket.socket() as taken:  # another worker's, bound after the choice
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        first = taken.getsockname()[1]
        choices = [first]
        free = service.free_port
        monkeypatch.setattr(service, "free_port", lambda: choices.pop() if choices else free())
        proc, port = await start_run(["run", "--config", str(config)], log)
    try:
        assert port != first
        assert f"cannot listen on 127.0.0.1:{first}" in log.read_text()
        assert proc.returncode is None
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}") as client:
            assert (await client.get("/healthz")).status_code == 200
    finally:
        proc.send_signal(signal.SIGTERM)
        assert await asyncio.wait_for(proc.wait(), 30) == 0
