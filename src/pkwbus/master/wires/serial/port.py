"""One RS-485 line: owns its link (the port and its state), runs one exchange at a time.

An exchange is one request telegram out and one answer (or an error) in.
A PKW job is a series of exchanges (:class:`PkwTransaction`), driven by the
planner (:mod:`pkwbus.master.planning.planner`), which may put other drives'
exchanges between its repeats. Its port (:attr:`TelegramPort.link`) owns the
port's state and back-off and tells its listeners of each change.

An exchange runs as a small state machine in the line's callbacks
(:meth:`TelegramPort.start`): the start pause is counted from the last byte
received, and whatever the caller does before starting the next exchange
uses it up; only what remains is waited, by a loop timer (a remainder of a
few microseconds is waited in place, cheaper than a wake-up). The request
goes out from that timer or at once, the answer is checked in the data
callback, and the caller's callback gets the result. No coroutine, lock or
future per exchange: :meth:`TelegramPort.exchange` wraps one exchange in a future
for callers that await.
"""

from __future__ import annotations

import asyncio
import enum
import logging
import time
from collections.abc import Callable

from pkwbus.link import Fence, Link, LinkState, PortError, PortSettings
from pkwbus.master.bus import Done as RunnerDone
from pkwbus.master.planning.answers import ErrorKind, ExchangeResult, Failure, Reply
from pkwbus.master.planning.plan import Send
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.serial.telegram import (
    BadChecksum,
    BadLength,
    Deframer,
    DeframerEvent,
    Telegram,
    Truncated,
    fc_lengths,
    uss_lengths,
)

__all__ = ["WAIT_IN_PLACE", "Done", "TelegramPort", "TraceHook"]

log = logging.getLogger(__name__)

TraceHook = Callable[[str, bytes], None]
Done = Callable[[ExchangeResult], None]

# A remainder of the start pause up to this long is waited in place: a loop
# timer's wake-up costs more CPU than that.
WAIT_IN_PLACE = 0.00002


class _State(enum.Enum):
    IDLE = "idle"
    PAUSE = "pause"  # the request waits for the start pause to end
    ANSWER = "answer"  # the request is out, the answer is awaited


class TelegramPort:
    """A line: one port, one exchange at a time."""

    def __init__(
        self,
        settings: PortSettings,
        protocol: Bus,
        *,
        timeout: float = 0.1,
        inter_char_timeout: float | None = None,
        trace: TraceHook | None = None,
        fence: Fence | None = None,
    ) -> None:
        self.protocol = protocol
        self.timeout = timeout
        self.inter_char_timeout = (
            inter_char_timeout if inter_char_timeout is not None else settings.inter_char_gap
        )
        self.trace = trace
        self.link = Link(settings, receiver=self._on_data, on_lost=self._on_lost, fence=fence)
        self.link.reconnect.add_listener(self._on_port)
        lengths = fc_lengths() if protocol is Bus.FC else uss_lengths()
        self._deframer = Deframer(lengths)
        self._lock = asyncio.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._state = _State.IDLE
        self._done: Done | None = None
        self._expect_adr = 0
        self._timeout = timeout
        self._started = 0.0
        self._send_timer: asyncio.TimerHandle | None = None
        self._gap_timer: asyncio.TimerHandle | None = None
        self._pending_error: ErrorKind | None = None
        self._sent = b""
        self._stray = True  # unread input may be waiting: discard it before the first request
        self._warned_echo = False
        self._wire_char = settings.char_time
        # One response timer, re-armed only when it fires early (not one per exchange).
        self._deadline = 0.0
        self._timer: asyncio.TimerHandle | None = None

    # -------------------------------------------------------------- API

    @property
    def is_open(self) -> bool:
        return self.link.is_open

    @property
    def busy(self) -> bool:
        """An exchange is in flight."""
        return self._done is not None

    @property
    def echo_heard(self) -> bool:
        """Whether the adapter echoed a request although the line's echo option is off."""
        return self._warned_echo

    async def open(self) -> None:
        """Open the port now; :class:`PortError` (and a back-off) when it cannot be opened."""
        self._loop = asyncio.get_running_loop()
        await self.link.open()

    async def close(self) -> None:
        await self.link.close()

    def abort(self, reason: str) -> None:
        """Give the port up after an unexpected error; it is reopened at back-off."""
        self.link.abort(reason)

    def _on_port(self, state: LinkState, error: str | None) -> None:
        if state is LinkState.OPEN:
            self._loop = asyncio.get_running_loop()
            self._stray = True  # unread input may be waiting: discard it before a request

    async def exchange(
        self, adr: int, telegram: bytes, timeout: float | None = None
    ) -> ExchangeResult:
        """Send ``telegram`` to the drive whose answers come from ``adr``, and wait for its
        answer."""
        async with self._lock:
            loop = self._loop = asyncio.get_running_loop()
            timeout = timeout or self.timeout
            if not self.link.is_open:
                try:
                    await self._ensure_open(loop.time() + timeout)
                except PortError as exc:
                    return Failure(ErrorKind.PORT, str(exc))
            waiter: asyncio.Future[ExchangeResult] = loop.create_future()
            self.send(adr, telegram, waiter.set_result, timeout)
            try:
                return await waiter
            except asyncio.CancelledError:
                self._abandon()
                raise

    async def started(self) -> None:
        """Nothing to do before the first request: the line discards stray input itself."""

    @property
    def sent_at(self) -> float:
        """Loop time the latest request was written."""
        return self._started

    def start(self, request: Send, done: RunnerDone[ExchangeResult]) -> None:
        """The runner's request: ``request``'s telegram, answered from its drive's address."""
        self.send(request.address, request.telegram, done)

    def send(self, adr: int, telegram: bytes, done: Done, timeout: float | None = None) -> None:
        """Begin one exchange; ``done`` gets its result, from a later callback.

        The request waits for what remains of the start pause. One exchange at
        a time: RuntimeError when one is in flight.
        """
        if self._done is not None:
            raise RuntimeError("an exchange is already in flight on this line")
        loop = self._loop
        if loop is None:
            loop = self._loop = asyncio.get_running_loop()
        self._done = done
        self._expect_adr = adr
        self._sent = telegram
        self._timeout = timeout or self.timeout
        self._state = _State.PAUSE
        link = self.link
        now = loop.time()
        wait = link.pause_left(now)
        if wait <= 0:
            self._send()
        elif wait <= WAIT_IN_PLACE:
            end = time.monotonic() + wait  # the loop's clock (asyncio's default)
            while time.monotonic() < end:
                pass
            self._send()
        elif link.fine_timers or not link.is_open:
            self._send_timer = loop.call_at(now + wait, self._on_send_timer)  # the pause's end
        else:  # a loop with millisecond timers: the link's thread-assisted pause
            self._send_timer = loop.call_later(0, self._pause_then_send)

    # --------------------------------------------------------- internals

    def _pause_then_send(self) -> None:
        self._send_timer = None
        loop = self._loop
        assert loop is not None
        task = loop.create_task(self._pause_on_coarse_loop(loop, self._done))
        task.add_done_callback(lambda t: t.cancelled() or t.exception())

    async def _pause_on_coarse_loop(
        self, loop: asyncio.AbstractEventLoop, done: Done | None
    ) -> None:
        wait = self.link.pause_left(loop.time())
        if wait > 0:
            await self.link._pause_for(loop, wait)
        if self._state is _State.PAUSE and self._done is done:  # not abandoned meanwhile
            self._send()

    def _on_send_timer(self) -> None:
        self._send_timer = None
        loop = self._loop
        assert loop is not None
        wait = self.link.pause_left(loop.time())
        if wait > WAIT_IN_PLACE:  # input came in meanwhile: the pause starts again
            self._send_timer = loop.call_later(wait, self._on_send_timer)
            return
        if wait > 0:
            end = time.monotonic() + wait
            while time.monotonic() < end:
                pass
        self._send()

    def _send(self) -> None:
        loop = self._loop
        assert loop is not None
        telegram = self._sent
        self._deframer.reset()
        self._pending_error = None
        stray, self._stray = self._stray, False
        try:
            self.link.write_now(telegram, discard=stray)
        except PortError as exc:
            self._finish(Failure(ErrorKind.PORT, str(exc)))
            return
        if self.trace:
            self.trace("tx", telegram)
        now = loop.time()
        self._started = now
        self._state = _State.ANSWER
        self._arm(loop, now + self._timeout + len(telegram) * self._wire_char)

    def _finish(self, result: ExchangeResult) -> None:
        """The exchange is over: the caller's callback gets ``result``."""
        if self._gap_timer is not None:
            self._cancel_gap_timer()
        if self._send_timer is not None:
            self._send_timer.cancel()
            self._send_timer = None
        if isinstance(result, Reply):
            self.link.usable()  # a drive answered: the port is usable
        if not isinstance(result, Reply) or self._deframer.buffered:
            self._stray = True  # what follows a bad answer must not start the next one
        done, self._done = self._done, None
        self._state = _State.IDLE
        if done is not None:
            done(result)

    def _abandon(self) -> None:
        """The caller stopped waiting: the exchange ends without a result."""
        if self._done is not None:
            self._done = None
            self._finish(Failure(ErrorKind.TIMEOUT, "abandoned"))

    async def _ensure_open(self, deadline: float) -> None:
        """Reopen the port, waiting out the back-off (never past ``deadline``)."""
        reconnect = self.link.reconnect
        if reconnect.next_attempt > deadline:
            raise PortError(reconnect.last_error or f"{self.link.settings.url} is not open")
        if not await self.link.reopen():
            raise PortError(reconnect.last_error or f"{self.link.settings.url} is not open")

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
        if self._state is not _State.ANSWER:
            return
        loop = self._loop
        assert loop is not None
        if self._deadline - loop.time() > 1e-4:
            self._timer = loop.call_at(self._deadline, self._on_timer)
            return
        self._on_timeout()

    def _on_lost(self, reason: str) -> None:
        if self._state is _State.ANSWER:
            self._finish(Failure(ErrorKind.PORT, reason))

    def _on_timeout(self) -> None:
        if not self.link.is_open:
            self._finish(Failure(ErrorKind.PORT, self.link.reconnect.last_error or "port lost"))
            return
        kind = self._pending_error or ErrorKind.TIMEOUT
        self._finish(Failure(kind, "no answer" if kind is ErrorKind.TIMEOUT else ""))

    def _on_data(self, data: bytes) -> None:
        if self.trace:
            self.trace("rx", data)
        if self._state is not _State.ANSWER:
            self._stray = True  # stale input between exchanges: dropped before the next request
            return
        self._handle_events(self._deframer.feed(data))
        if self._gap_timer is not None:
            self._cancel_gap_timer()
        if self._state is _State.ANSWER and self._deframer.buffered:
            loop = self._loop
            assert loop is not None
            self._gap_timer = loop.call_later(self.inter_char_timeout, self._on_gap)

    def _on_gap(self) -> None:
        self._gap_timer = None
        if self._state is _State.ANSWER:
            self._handle_events(self._deframer.flush())

    def _cancel_gap_timer(self) -> None:
        if self._gap_timer is not None:
            self._gap_timer.cancel()
            self._gap_timer = None

    def _handle_events(self, events: list[DeframerEvent]) -> None:
        for event in events:
            if isinstance(event, Telegram):
                sent = self._sent
                if sent and event.data == sent[3:-1] and event.adr == sent[2]:
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
                loop = self._loop
                assert loop is not None
                duration = loop.time() - self._started
                self._finish(Reply(event.adr, event.data, duration))
                return
            if isinstance(event, BadChecksum):
                self._finish(Failure(ErrorKind.CHECKSUM, event.raw.hex(" ")))
                return
            if isinstance(event, Truncated):
                self._finish(Failure(ErrorKind.LENGTH, f"truncated: {event.raw.hex(' ')}"))
                return
            if isinstance(event, BadLength):
                self._pending_error = ErrorKind.LENGTH
