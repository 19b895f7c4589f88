"""One RS-485 line: owns its link and its reconnect object, runs one exchange at a time.

An exchange is one request telegram out and one answer (or an error) in.
A PKW job is a series of exchanges (:class:`PkwTransaction`), driven by the
planner (:mod:`pkwbus.master.planner`), which may put other drives'
exchanges between its repeats. The line is the one owner of its port: it
opens, aborts and closes it and tells :attr:`Line.reconnect` of each
change; others listen there.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from pkwbus.link import Link, PortError, PortSettings, Reconnect
from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import (
    ErrorKind,
    ExchangeResult,
    Failure,
    Reply,
)
from pkwbus.protocol.telegram import (
    BadChecksum,
    BadLength,
    Deframer,
    DeframerEvent,
    Protocol,
    Telegram,
    Truncated,
    fc_lengths,
    uss_lengths,
)

log = logging.getLogger(__name__)

TraceHook = Callable[[str, bytes], None]


class Line:
    """A line: one port, one exchange at a time."""

    def __init__(
        self,
        settings: PortSettings,
        protocol: Protocol,
        *,
        timeout: float = 0.1,
        inter_char_timeout: float | None = None,
        trace: TraceHook | None = None,
    ) -> None:
        self.protocol = protocol
        self.timeout = timeout
        self.inter_char_timeout = (
            inter_char_timeout if inter_char_timeout is not None else settings.inter_char_gap
        )
        self.trace = trace
        self.link = Link(settings, receiver=self._on_data, on_lost=self._on_lost)
        self.reconnect = Reconnect(settings.reopen_initial, settings.reopen_cap)
        lengths = fc_lengths() if protocol is Protocol.FC else uss_lengths()
        self._deframer = Deframer(lengths)
        self._lock = asyncio.Lock()
        self._waiter: asyncio.Future[ExchangeResult] | None = None
        self._expect_adr = 0
        self._started = 0.0
        self._gap_timer: asyncio.TimerHandle | None = None
        self._pending_error: ErrorKind | None = None
        self._sent = b""
        self._warned_echo = False
        # One response timer, re-armed only when it fires early (not one per exchange).
        self._deadline = 0.0
        self._timer: asyncio.TimerHandle | None = None

    # -------------------------------------------------------------- API

    @property
    def is_open(self) -> bool:
        return self.link.is_open

    async def open(self) -> None:
        """Open the port now; :class:`PortError` (and a back-off) when it cannot be opened."""
        try:
            await self.link.open()
        except PortError as exc:
            self.reconnect.failed(str(exc), asyncio.get_running_loop().time())
            raise
        self.reconnect.opened()

    async def close(self) -> None:
        await self.link.close()
        self.reconnect.closed()

    def abort(self, reason: str) -> None:
        """Give the port up after an unexpected error; it is reopened at back-off."""
        self.link.abort()
        self.reconnect.failed(reason, asyncio.get_running_loop().time())

    async def exchange(
        self, target: DriveTarget, telegram: bytes, timeout: float | None = None
    ) -> ExchangeResult:
        """Send ``telegram`` to ``target`` and wait for its answer."""
        async with self._lock:
            return await self._exchange(target.adr, telegram, timeout or self.timeout)

    # --------------------------------------------------------- internals

    async def _exchange(self, adr: int, telegram: bytes, timeout: float) -> ExchangeResult:
        loop = asyncio.get_running_loop()
        link = self.link
        try:
            if not link.is_open:
                await self._ensure_open(loop.time() + timeout)
            self._deframer.reset()
            self._pending_error = None
            await link.send(telegram)
        except PortError as exc:
            return Failure(ErrorKind.PORT, str(exc))
        if self.trace:
            self.trace("tx", telegram)
        now = loop.time()
        self._started = now
        self._expect_adr = adr
        self._sent = telegram
        waiter: asyncio.Future[ExchangeResult] = loop.create_future()
        self._waiter = waiter
        self._arm(loop, now + timeout + link.settings.wire_time(len(telegram)))
        try:
            return await waiter
        finally:
            if self._gap_timer is not None:
                self._cancel_gap_timer()
            self._waiter = None

    async def _ensure_open(self, deadline: float) -> None:
        """Reopen the port, waiting out the back-off (never past ``deadline``)."""
        reconnect = self.reconnect
        wait = reconnect.wait(asyncio.get_running_loop().time())
        if wait > 0:
            if reconnect.next_attempt > deadline:
                raise PortError(reconnect.last_error or f"{self.link.settings.url} is not open")
            await asyncio.sleep(wait)
        await self.open()

    def _arm(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        self._deadline = deadline
        timer = self._timer
        if timer is not None:
            if timer.when() <= deadline:
                return  # fires first, sees the new deadline and re-arms
            timer.cancel()
        self._timer = loop.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        waiter = self._waiter
        if waiter is None or waiter.done():
            return
        loop = asyncio.get_running_loop()
        if self._deadline - loop.time() > 1e-4:
            self._timer = loop.call_at(self._deadline, self._on_timer)
            return
        self._on_timeout(waiter)

    def _resolve(self, result: ExchangeResult) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(result)

    def _on_lost(self, reason: str) -> None:
        self.reconnect.failed(reason, asyncio.get_running_loop().time())
        self._resolve(Failure(ErrorKind.PORT, reason))

    def _on_timeout(self, waiter: asyncio.Future[ExchangeResult]) -> None:
        if waiter.done():
            return
        if not self.link.is_open:
            waiter.set_result(Failure(ErrorKind.PORT, self.reconnect.last_error or "port lost"))
            return
        kind = self._pending_error or ErrorKind.TIMEOUT
        waiter.set_result(Failure(kind, "no answer" if kind is ErrorKind.TIMEOUT else ""))

    def _on_data(self, data: bytes) -> None:
        if self.trace:
            self.trace("rx", data)
        if self._waiter is None:
            return  # stale input between exchanges: dropped before the next request
        self._handle_events(self._deframer.feed(data))
        self._cancel_gap_timer()
        if self._waiter is not None and self._deframer.buffered:
            loop = asyncio.get_running_loop()
            self._gap_timer = loop.call_later(self.inter_char_timeout, self._on_gap)

    def _on_gap(self) -> None:
        self._gap_timer = None
        self._handle_events(self._deframer.flush())

    def _cancel_gap_timer(self) -> None:
        if self._gap_timer is not None:
            self._gap_timer.cancel()
            self._gap_timer = None

    def _handle_events(self, events: list[DeframerEvent]) -> None:
        for event in events:
            if isinstance(event, Telegram):
                if self._sent and event.data == self._sent[3:-1] and event.adr == self._sent[2]:
                    # Our own request, heard back: an adapter that echoes although the
                    # line's echo option is off. Never taken for the drive's answer.
                    self._sent = b""
                    if not self._warned_echo:
                        self._warned_echo = True
                        log.warning(
                            "%s echoes our requests: set echo: true for this line",
                            self.link.settings.url,
                        )
                    continue
                if event.adr != self._expect_adr:
                    # Another station (or a late answer to an earlier request): keep
                    # listening for ours; reported as an address error if it never comes.
                    self._pending_error = ErrorKind.ADDRESS
                    continue
                duration = asyncio.get_running_loop().time() - self._started
                self._resolve(Reply(event.adr, event.data, duration))
                return
            if isinstance(event, BadChecksum):
                self._resolve(Failure(ErrorKind.CHECKSUM, event.raw.hex(" ")))
                return
            if isinstance(event, Truncated):
                self._resolve(Failure(ErrorKind.LENGTH, f"truncated: {event.raw.hex(' ')}"))
                return
            if isinstance(event, BadLength):
                self._pending_error = ErrorKind.LENGTH
