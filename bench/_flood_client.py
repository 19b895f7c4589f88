"""A flood of HTTP connections, run in its own process by connection_flood.py.

    python -m bench._flood_client HOST PORT IDLE PARALLEL HOLD_SECONDS

Opens IDLE connections that send nothing, then PARALLEL connections that
each send one GET /healthz at once, holds everything for HOLD_SECONDS and
prints one JSON object: how many connections the service kept open or
closed at once, and how the requests were answered.
"""

from __future__ import annotations

import asyncio
import json
import sys


async def _idle(host: str, port: int) -> tuple[asyncio.StreamReader, asyncio.StreamWriter] | None:
    try:
        return await asyncio.open_connection(host, port)
    except OSError:
        return None


async def _get(host: str, port: int) -> str:
    try:
        reader, writer = await asyncio.open_connection(host, port)
    except OSError:
        return "connect_failed"
    try:
        writer.write(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        await writer.drain()
        head = await asyncio.wait_for(reader.read(12), 30)
    except (OSError, TimeoutError):
        return "reset"
    finally:
        writer.close()
    if not head:
        return "refused"
    return head.decode(errors="replace").split(" ")[1] if b" " in head else "garbled"


async def main(host: str, port: int, idle: int, parallel: int, hold: float) -> dict[str, object]:
    conns = [await _idle(host, port) for _ in range(idle)]
    opened = [c for c in conns if c is not None]
    await asyncio.sleep(0.5)
    # Connections the service refused are at end of file at once.

    async def at_end(reader: asyncio.StreamReader) -> bool:
        try:
            return await asyncio.wait_for(reader.read(1), 0.2) == b""
        except (TimeoutError, OSError):
            return False

    closed = sum(await asyncio.gather(*(at_end(r) for r, _ in opened)))
    answers = await asyncio.gather(*(_get(host, port) for _ in range(parallel)))
    await asyncio.sleep(hold)
    for _, writer in opened:
        writer.close()
    counts: dict[str, int] = {}
    for a in answers:
        counts[a] = counts.get(a, 0) + 1
    return {
        "idle_opened": len(opened),
        "idle_closed_at_once": closed,
        "idle_connect_failed": idle - len(opened),
        "parallel": counts,
    }


if __name__ == "__main__":
    host, port, idle, parallel, hold = sys.argv[1:6]
    print(json.dumps(asyncio.run(main(host, int(port), int(idle), int(parallel), float(hold)))))
