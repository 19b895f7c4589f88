"""HTTP connections: a bound on how many are open, and no connection left idle forever.

uvicorn's own ``limit_concurrency`` answers 503 once the limit is reached but
still accepts every connection, so each idle client keeps a file descriptor
and a flood of them starves the process (and the serial ports it must
reopen). Here a connection beyond ``max_connections`` is closed as soon as
it is accepted, and the refusals are logged once per ``LOG_EVERY`` seconds
with their count. A connection that sends nothing is closed after uvicorn's
keep-alive timeout, as one that has finished a request would be, and one
that has begun a request must complete its headers within
``HEADER_TIMEOUT`` seconds: a client sending a byte now and then cannot hold
a connection for ever.
"""

from __future__ import annotations

import asyncio
import logging

from uvicorn.protocols.http.h11_impl import H11Protocol

__all__ = ["HEADER_TIMEOUT", "LOG_EVERY", "ConnectionLimit", "bounded_protocol"]

log = logging.getLogger("pkwbus.service.http")  # the name its log lines have always carried

LOG_EVERY = 10.0
HEADER_TIMEOUT = 10.0


class ConnectionLimit:
    """The refusals of one server: counted, and logged at most once per ``LOG_EVERY``."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.refused = 0
        self._unlogged = 0
        self._logged_at: float | None = None

    def refuse(self, now: float, open_now: int) -> None:
        self.refused += 1
        self._unlogged += 1
        if self._logged_at is None or now - self._logged_at >= LOG_EVERY:
            log.warning(
                "HTTP: refused %d connection(s): %d open, the limit is %d (api.max_connections)",
                self._unlogged,
                open_now,
                self.limit,
            )
            self._unlogged = 0
            self._logged_at = now


def bounded_protocol(limit: ConnectionLimit) -> type[H11Protocol]:
    """An h11 protocol class for uvicorn that refuses connections beyond ``limit``."""

    class BoundedH11Protocol(H11Protocol):
        _refused = False

        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
            if len(self.connections) >= limit.limit:
                self._refused = True
                transport.abort()
                limit.refuse(self.loop.time(), len(self.connections))
                return
            super().connection_made(transport)
            # Until its first byte, a connection is idle like one between requests.
            self.timeout_keep_alive_task = self.loop.call_later(
                self.timeout_keep_alive, self.timeout_keep_alive_handler
            )

        _headers_due: asyncio.TimerHandle | None = None

        def connection_lost(self, exc: Exception | None) -> None:
            if not self._refused:
                self._headers_arrived()
                super().connection_lost(exc)

        def data_received(self, data: bytes) -> None:
            if self._refused:
                return
            super().data_received(data)
            if self.cycle is not None and not self.cycle.response_complete:
                self._headers_arrived()  # a request is being served
            elif self._headers_due is None and not self.transport.is_closing():
                self._headers_due = self.loop.call_later(HEADER_TIMEOUT, self._too_slow)

        def on_response_complete(self) -> None:
            self._headers_arrived()
            super().on_response_complete()

        def _headers_arrived(self) -> None:
            if self._headers_due is not None:
                self._headers_due.cancel()
                self._headers_due = None

        def _too_slow(self) -> None:
            self._headers_due = None
            if not self.transport.is_closing():
                log.info(
                    "HTTP: closed a connection whose request headers took over %g s", HEADER_TIMEOUT
                )
                self.transport.close()

    return BoundedH11Protocol
