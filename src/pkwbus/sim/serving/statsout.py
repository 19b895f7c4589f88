"""The simulator's counters as JSON while it runs: a file rewritten atomically, and GET /stats."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import tempfile

from pkwbus.sim.serving.stats import SimStats

__all__ = ["StatsServer", "keep_stats_file", "write_stats_file"]


def write_stats_file(stats: SimStats, path: str) -> None:
    """Write the counters to ``path`` by rename, so a reader never sees half a file."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".stats-", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            json.dump(stats.as_dict(), out, indent=1, sort_keys=True)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


async def keep_stats_file(stats: SimStats, path: str, interval: float) -> None:
    """Rewrite the stats file every ``interval`` seconds until cancelled, and once at the end."""
    try:
        while True:
            write_stats_file(stats, path)
            await asyncio.sleep(interval)
    finally:
        write_stats_file(stats, path)


class StatsServer:
    """A minimal HTTP/1.0 server: ``GET /stats`` answers the counters as JSON."""

    def __init__(self, stats: SimStats) -> None:
        self.stats = stats
        self.port = 0
        self._server: asyncio.Server | None = None

    async def start(self, host: str, port: int) -> None:
        self._server = await asyncio.start_server(self._client, host, port)
        self.port = self._server.sockets[0].getsockname()[1]

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            async with asyncio.timeout(5):
                line = await reader.readline()
                while (await reader.readline()).strip():
                    pass  # headers
            parts = line.decode("latin-1").split()
            if parts[:2] == ["GET", "/stats"]:
                body = json.dumps(self.stats.as_dict()).encode()
                writer.write(_response("200 OK", body))
            else:
                writer.write(_response("404 Not Found", b'{"error": "try GET /stats"}'))
            await writer.drain()
        except (TimeoutError, ConnectionError):
            pass
        finally:
            writer.close()

    async def close(self) -> None:
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()


def _response(status: str, body: bytes) -> bytes:
    head = (
        f"HTTP/1.0 {status}\r\nContent-Type: application/json\r\n"
        f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n"
    )
    return head.encode("latin-1") + body
