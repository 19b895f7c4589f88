"""The process tests' start of `pkwbus run`: it binds port 0 and names the port the system
gave it, so no port is chosen before the bind that another test worker could take."""

from __future__ import annotations

import asyncio
import signal
from pathlib import Path

import httpx

from .service import start_run

CONFIG = (
    "lines:\n"
    "  - name: l1\n    port: sim://fc?drives=1\n    protocol: fc\n    baudrate: 19200\n"
    "    drives: [{name: a, address: 1, poll: [{parameter: '16-13', every: 1s}]}]\n"
)


async def test_two_services_on_port_0_each_name_the_port_they_got(tmp_path: Path) -> None:
    started = []
    for n in range(2):
        folder = tmp_path / str(n)
        folder.mkdir()
        config = folder / "c.yaml"
        config.write_text(f"audit_db: {folder / 'audit.sqlite'}\n{CONFIG}")
        started.append(await start_run(["run", "--config", str(config)], folder / "err.log"))
    try:
        ports = [port for _, port in started]
        assert len(set(ports)) == 2 and all(ports)
        for port in ports:
            async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}") as client:
                assert (await client.get("/healthz")).status_code == 200
    finally:
        for proc, _ in started:
            proc.send_signal(signal.SIGTERM)
        for proc, _ in started:
            assert await asyncio.wait_for(proc.wait(), 30) == 0
