"""The composition root of `pkwbus run`: lines, HTTP server, signals, shutdown.

SIGTERM or SIGINT: stop taking new jobs, let every line finish the exchange
in flight, close the ports, stop the HTTP server, exit 0.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import socket
from collections.abc import Iterator

import uvicorn
from fastapi import FastAPI

from pkwbus.service.runtime import Runtime

log = logging.getLogger(__name__)


MAX_HTTP_CONNECTIONS = 256


class ListenError(Exception):
    """The HTTP address cannot be bound."""


class _Server(uvicorn.Server):
    """uvicorn without its own signal handling: the service owns the signals."""

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        yield


def bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    # IPPROTO_TCP, not 0: asyncio sets TCP_NODELAY only on sockets that say TCP, and
    # without it every answer waits ~40 ms for the client's delayed ACK (Nagle).
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise ListenError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    sock.listen(128)
    sock.setblocking(False)
    return sock


async def serve(runtime: Runtime, app: FastAPI, sock: socket.socket) -> None:
    """Run until SIGTERM/SIGINT, then shut down in order."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    # The loop waits with select() (link.eventloop), which handles file descriptors
    # below 1024: a bounded number of HTTP connections keeps the process far below.
    config = uvicorn.Config(
        app,
        log_config=None,
        access_log=False,
        lifespan="off",
        timeout_graceful_shutdown=2,
        limit_concurrency=MAX_HTTP_CONNECTIONS,
    )
    server = _Server(config)
    await runtime.start()
    server_task = asyncio.create_task(server.serve(sockets=[sock]), name="http")
    stop_task = asyncio.create_task(stop.wait(), name="signal")
    try:
        await asyncio.wait({server_task, stop_task}, return_when=asyncio.FIRST_COMPLETED)
        log.info("stopping: finishing the exchanges in flight")
    finally:
        await runtime.stop()
        server.should_exit = True
        try:
            await asyncio.wait_for(server_task, 5.0)
        except asyncio.CancelledError:
            pass
        except Exception as exc:  # the service is stopping anyway: say so, no traceback
            log.warning("HTTP server: %s", exc or type(exc).__name__)
        stop_task.cancel()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.remove_signal_handler(sig)
    log.info("stopped")
