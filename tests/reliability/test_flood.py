"""A flood of HTTP connections: the service refuses what is over its limit, stays up and
keeps polling."""

from __future__ import annotations

import asyncio
import signal
from pathlib import Path

import httpx

from pkwbus.sim import SimTiming, Simulator

from .helpers import record_wire
from .service import Service, wait_for

IDLE = 1_200  # above select()'s 1024 descriptors, and above the limit below
LIMIT = 300
PARALLEL = 600


async def _open_idle(port: int, n: int) -> list[asyncio.StreamWriter]:
    writers = []
    for _ in range(n):
        try:
            _, writer = await asyncio.open_connection("127.0.0.1", port)
        except OSError:
            continue
        writers.append(writer)
    return writers


async def _get(client: httpx.AsyncClient, path: str) -> int | None:
    try:
        return (await client.get(path)).status_code
    except httpx.TransportError:
        return None  # refused: closed at once by the service


async def test_a_connection_flood_is_refused_and_polling_goes_on(tmp_path: Path) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.002), seed=1, catalog="danfoss-fc")
    wire = record_wire(sim)
    end = await sim.serve_tcp("127.0.0.1", 0)
    service = Service(tmp_path, end.url, every="50ms", api={"max_connections": LIMIT})
    idle: list[asyncio.StreamWriter] = []
    try:
        await service.start()
        await wait_for(lambda: wire.requests[1] > 0, 10)
        idle = await _open_idle(service.port, IDLE)
        assert len(idle) > 1024 - 100  # the client side did open them
        # Polling goes on while the idle connections are held.
        before = wire.requests[1]
        await wait_for(lambda: wire.requests[1] >= before + 10, 20)
        limits = httpx.Limits(max_connections=PARALLEL, max_keepalive_connections=0)
        async with httpx.AsyncClient(base_url=service.base, timeout=30, limits=limits) as client:
            codes = await asyncio.gather(*(_get(client, "/healthz") for _ in range(PARALLEL)))
        assert set(codes) <= {200, None}, set(codes)
        assert service.proc is not None and service.proc.returncode is None
        before = wire.requests[1]
        await wait_for(lambda: wire.requests[1] >= before + 10, 20)
        for writer in idle:
            writer.close()
        idle = []
        async with service.client() as client:

            async def answers() -> bool:
                return await _get(client, "/readyz") == 200

            deadline = asyncio.get_running_loop().time() + 20
            while not await answers():
                assert asyncio.get_running_loop().time() < deadline
                await asyncio.sleep(0.2)
        service.signal(signal.SIGTERM)
        assert await service.wait(10) == 0
        log = service.log.read_text()
        assert "refused" in log and "api.max_connections" in log, log[-2000:]
        assert "Traceback" not in log and "internal error" not in log, log[-2000:]
    finally:
        for writer in idle:
            writer.close()
        await service.stop()
        await end.close()
