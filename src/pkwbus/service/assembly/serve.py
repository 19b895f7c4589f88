"""The running service from start to stop: the HTTP address bound, the lines and the
HTTP server started, signals, shutdown in order (:func:`serve`); what
:mod:`pkwbus.service.assembly.root` runs once it has built them.

From the start to the stop the event loop is watched
(:mod:`pkwbus.service.metrics.event_loop`): ``pkwbus_event_loop_lag_seconds``, and a
log line for a callback that holds it.

SIGTERM or SIGINT: stop taking new jobs, let every line finish the exchange
in flight, close the ports, stop the HTTP server, exit 0. SIGHUP reloads the
configuration file (:mod:`pkwbus.service.assembly.reload`), one reload after
the other; a service without a file to reload ignores it (logged).

Raises :class:`ListenError` when the HTTP address cannot be bound.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import gc
import logging
import resource
import signal
import socket
from collections.abc import Iterator
from typing import Protocol

import uvicorn
from fastapi import FastAPI

from pkwbus.errors import PkwbusError
from pkwbus.service.config import LISTEN_ENV
from pkwbus.service.http.connections import ConnectionLimit, bounded_protocol
from pkwbus.service.metrics.event_loop import LoopWatch
from pkwbus.service.runtime import Runtime

__all__ = [
    "RELOAD_SIGNAL",
    "SPARE_DESCRIPTORS",
    "STOP_SIGNALS",
    "ListenError",
    "bind",
    "raise_open_files_limit",
    "serve",
    "settle_heap",
]

log = logging.getLogger("pkwbus.service.app")  # the name its log lines have always carried

STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT)
RELOAD_SIGNAL = signal.SIGHUP


class Hangup(Protocol):
    """What a SIGHUP asks for: a reload (service.http.reload.Reloads)."""

    async def by_signal(self, name: str = "SIGHUP") -> None: ...

    async def close(self) -> None: ...


class ListenError(PkwbusError):
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
        hint = ""
        if exc.errno == errno.EADDRINUSE:
            hint = (
                " (another program, or another pkwbus, listens there: choose another "
                f"address with --listen HOST:PORT, {LISTEN_ENV} or listen: in the configuration)"
            )
        shown = f"[{host}]" if ":" in host else host
        raise ListenError(f"cannot listen on {shown}:{port}: {exc.strerror or exc}{hint}") from None
    sock.listen(128)
    sock.setblocking(False)
    return sock


def raise_open_files_limit(needed: int) -> None:
    """Lift the soft limit of open files towards the hard one, so ``needed`` fit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY or soft >= needed:
        return
    target = needed if hard == resource.RLIM_INFINITY else min(needed, hard)
    if target > soft:
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    if soft < needed:
        log.warning(
            "open files are limited to %d (ulimit -n): fewer than the %d HTTP connections "
            "api.max_connections allows plus the ports; lower api.max_connections",
            soft,
            needed - SPARE_DESCRIPTORS,
        )


# Descriptors besides HTTP connections: ports, the audit database, the listener, logs.
SPARE_DESCRIPTORS = 64


def settle_heap() -> None:
    """Put what start-up made (configuration, catalogs, metric series: some 300,000
    objects at eight lines of 126 drives) out of the cyclic garbage collector's sight.

    A full collection then walks only what the running service keeps making, about
    20 ms at that size instead of 200-300 ms, during which every line would stand.
    """
    gc.collect()
    gc.freeze()
    log.debug("start-up objects kept out of the garbage collector: %d", gc.get_freeze_count())


async def serve(
    runtime: Runtime,
    app: FastAPI,
    sock: socket.socket,
    *,
    max_connections: int = 500,
    limit: ConnectionLimit | None = None,
    on_hangup: Hangup | None = None,
) -> None:
    """Run until SIGTERM or SIGINT, then shut down in order; a SIGHUP reloads
    (``on_hangup``)."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    received: list[str] = []
    reloads: set[asyncio.Task[None]] = set()

    def on_signal(sig: signal.Signals) -> None:
        received.append(sig.name)
        stop.set()

    def on_hup() -> None:
        if on_hangup is None:
            log.warning("SIGHUP: this service has no configuration file to reload")
            return
        log.info("SIGHUP: reloading the configuration")
        task = asyncio.create_task(on_hangup.by_signal(), name="reload")
        reloads.add(task)
        task.add_done_callback(reloads.discard)

    signals = [s for s in STOP_SIGNALS if signal.getsignal(s) is not signal.SIG_IGN]
    for sig in signals:
        loop.add_signal_handler(sig, on_signal, sig)
    # A SIGHUP ignored by whoever started the service (nohup) stays ignored.
    if signal.getsignal(RELOAD_SIGNAL) is not signal.SIG_IGN:
        loop.add_signal_handler(RELOAD_SIGNAL, on_hup)
        signals.append(RELOAD_SIGNAL)
    limit = limit or ConnectionLimit(max_connections)
    raise_open_files_limit(limit.limit + SPARE_DESCRIPTORS)
    config = uvicorn.Config(
        app,
        log_config=None,
        access_log=False,
        lifespan="off",
        timeout_graceful_shutdown=2,
        http=bounded_protocol(limit),
    )
    server = _Server(config)
    settle_heap()
    # How late the loop runs, and which callback held it: from here to the end (the heap
    # settled above is the start's, no callback's).
    watch = LoopWatch(runtime.registry)
    watch.start()
    await runtime.start()
    server_task = asyncio.create_task(server.serve(sockets=[sock]), name="http")
    stop_task = asyncio.create_task(stop.wait(), name="signal")
    try:
        await asyncio.wait({server_task, stop_task}, return_when=asyncio.FIRST_COMPLETED)
        by = f" ({received[0]})" if received else ""
        log.info("stopping%s: finishing the exchanges in flight", by)
    finally:
        if RELOAD_SIGNAL in signals:
            loop.remove_signal_handler(RELOAD_SIGNAL)
            signals.remove(RELOAD_SIGNAL)
        if on_hangup is not None:  # no reload from now on; one under way finishes first
            with contextlib.suppress(Exception):
                await asyncio.wait_for(on_hangup.close(), 60.0)
        for task in list(reloads):
            with contextlib.suppress(Exception):
                await asyncio.wait_for(asyncio.shield(task), 5.0)
        await runtime.stop()
        server.should_exit = True
        try:
            await asyncio.wait_for(server_task, 5.0)
        except asyncio.CancelledError:
            pass
        except Exception as exc:  # the service is stopping anyway: say so, no traceback
            log.warning("HTTP server: %s", exc or type(exc).__name__)
        stop_task.cancel()
        for sig in signals:
            loop.remove_signal_handler(sig)
        watch.stop()
    log.info("stopped")
