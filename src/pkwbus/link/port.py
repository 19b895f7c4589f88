"""A serial port (device path or pyserial URL) seen as a half-duplex RS-485 link.

The link writes one request at a time after the line has been quiet for the
start pause, counted from the last byte received (or the end of its own
last request on the wire), optionally strips the echo of its own
transmission, and hands every received chunk to its owner's receiver.
:meth:`Link.send` waits out the pause and discards stale input itself; a
caller that runs its exchanges from callbacks asks :meth:`Link.pause_left`
and writes with :meth:`Link.write_now`, discarding input only when stray
bytes arrived. When the port disappears it tells its owner once
(``on_lost``).

The link is the one owner of its port's state (:attr:`Link.reconnect`): every
opening, failure, loss and close is told there, to its listeners, and
:meth:`Link.reopen` opens the port again once the back-off allows.

Raises :class:`PortError` when the port cannot be opened, is not open or was lost.
"""

from __future__ import annotations

import asyncio
import logging
import math
import os
import termios
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import serial
import serial.rs485

from pkwbus.link.eventloop import has_fine_timers
from pkwbus.link.fence import ALWAYS_OPEN, Fence, fence_closed, fenced_reason
from pkwbus.link.ownership import PortBusy
from pkwbus.link.reconnect import LinkState, Reconnect
from pkwbus.link.serialport import (
    apply_adapter_settings,
    closer,
    describe_error,
    is_pty,
    open_port,
    raw_fd,
    release,
)
from pkwbus.link.settings import PARITIES, PortError, PortSettings, Rs485Mode
from pkwbus.link.transport import SerialTransport, wrap_transport
from pkwbus.waiting import wait_event

__all__ = [
    "PARITIES", "Link", "LinkState", "PortError", "PortSettings", "Rs485Mode",
    "apply_adapter_settings", "is_pty",
]  # fmt: skip

log = logging.getLogger(__name__)

# On a loop with an epoll selector waits last whole milliseconds, rounded up: a
# pause of 0.3 ms would last about 1 ms. There the part of a pause below this is
# waited out by a helper thread (``time.sleep`` has microsecond resolution);
# pkwbus's own loop (link.eventloop) needs no thread.
LOOP_TIMER_RESOLUTION = 0.001

Receiver = Callable[[bytes], None]
LostListener = Callable[[str], None]


class _Protocol(asyncio.Protocol):
    """One per opening: the end of an earlier transport is not the current port's."""

    def __init__(self, link: Link) -> None:
        self._link = link

    def data_received(self, data: bytes) -> None:
        self._link._on_data(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self._link._on_lost(self, exc)


class Link:
    """One port. Owned by one line, which gives its callbacks once; nothing else touches it."""

    def __init__(
        self,
        settings: PortSettings,
        *,
        receiver: Receiver | None = None,
        on_lost: LostListener | None = None,
        fence: Fence | None = None,
    ) -> None:
        self.settings = settings
        # Hot standby: no opening and no byte written once the fence closed (link.fence).
        self.fence = fence if fence is not None else ALWAYS_OPEN
        self._receiver = receiver
        self._on_lost_cb = on_lost
        self._transport: SerialTransport | None = None
        self._protocol: _Protocol | None = None
        self._state = LinkState.CLOSED
        self._quiet_at = 0.0
        self._echo = b""
        self._closing = False
        self._fd = -1
        self._instance: Any = None  # the open pyserial port, whose lock goes when it is left
        self._pause = settings.start_pause
        self._char_time = settings.char_time
        self._fine_timer: ThreadPoolExecutor | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._echo_on = settings.echo
        self._fine = False
        self.reconnect = Reconnect(settings.reopen_initial, settings.reopen_cap)

    @property
    def state(self) -> LinkState:
        return self._state

    @property
    def is_open(self) -> bool:
        return self._state is LinkState.OPEN

    # ------------------------------------------------------------ opening

    async def open(self) -> None:
        """Open now; :class:`PortError` with the reason when the port cannot be opened."""
        loop = asyncio.get_running_loop()
        s = self.settings
        error: PortError
        if fence_closed(self.fence):
            error = PortError(f"cannot open {s.url}: {fenced_reason(self.fence)}")
            self._state = LinkState.FAILED
            self.reconnect.failed(str(error), loop.time())
            raise error
        try:
            instance = await loop.run_in_executor(None, open_port, s)
        except PortBusy as exc:
            error = PortBusy(f"cannot open {exc}")
        except (serial.SerialException, OSError, ValueError, termios.error) as exc:
            reason = describe_error(exc).split(f"{s.url}: ", 1)[-1]
            error = PortError(f"cannot open {s.url}: {reason}")
        else:
            self._opened(loop, instance)
            return
        self._state = LinkState.FAILED
        self.reconnect.failed(str(error), loop.time())
        raise error from None

    def _opened(self, loop: asyncio.AbstractEventLoop, instance: Any) -> None:
        s = self.settings
        self._closing = False
        closer.start()
        self._protocol = protocol = _Protocol(self)
        self._transport = wrap_transport(loop, protocol, instance, s.url)
        self._fd = raw_fd(instance)
        self._instance = instance
        self._loop = loop
        self._fine = has_fine_timers(loop)
        self._quiet_at = loop.time()
        self._state = LinkState.OPEN
        self.reconnect.opened(loop.time())

    async def reopen(self, wake: asyncio.Event | None = None) -> bool:
        """Open the port once its back-off has passed; True when it is open.

        A ``wake`` set meanwhile (a job came in) ends the wait early with the
        back-off still standing: False, nothing tried. A port that cannot be
        opened is told to the listeners and waits a longer back-off.
        """
        loop = asyncio.get_running_loop()
        wait = self.reconnect.wait(loop.time())
        if wait > 0:
            if wake is None:
                await asyncio.sleep(wait)
            else:
                wake.clear()
                if await wait_event(wake, wait):
                    return False
        try:
            await self.open()
        except PortError:
            return False  # told to the listeners
        return True

    def _leave(self) -> None:
        """The port is given up: its lock goes at once, so that this process may open it
        again while the old transport still ends (writes what it holds, closes)."""
        instance, self._instance = self._instance, None
        if instance is not None:
            release(instance)

    async def close(self) -> None:
        self._closing = True
        self._leave()
        transport, self._transport = self._transport, None
        self._protocol, self._fd = None, -1
        if transport is not None:
            transport.close()
            await asyncio.sleep(0)  # let connection_lost run
        if self._fine_timer is not None:
            self._fine_timer.shutdown(wait=False)
            self._fine_timer = None
        self._state = LinkState.CLOSED
        self.reconnect.closed()

    def usable(self) -> None:
        """A station answered: the port is usable, its back-off starts afresh (said in the
        log where openings of the outage were not). At each answer: one test while no
        outage is on (its back-off is fresh then: every failure starts an outage)."""
        if not self.reconnect.outage:
            return
        openings = self.reconnect.usable()
        if openings:
            log.info("%s: a station answers again, after %d openings", self.settings.url, openings)

    def abort(self, reason: str = "given up") -> None:
        """Give the port up at once (an unexpected error); reopened after a back-off."""
        transport, self._transport = self._transport, None
        self._protocol, self._fd = None, -1
        self._closing = True
        self._leave()
        if transport is not None:
            transport.abort()
        self._state = LinkState.FAILED
        self.reconnect.failed(reason, asyncio.get_running_loop().time())

    # ------------------------------------------------------------ traffic

    async def send(self, data: bytes) -> None:
        """Write ``data`` once the line has been quiet for the start pause; drop stale input.

        Stale input is dropped before every request: the PROFIBUS DP line's
        way, where a late answer of a station asked again must not be taken
        for the answer to the new request.
        """
        transport = self._transport
        if transport is None or self._state is not LinkState.OPEN:
            raise PortError(f"{self.settings.url} is not open")
        loop = asyncio.get_running_loop()
        wait = self._quiet_at + self._pause - loop.time()
        if wait > 0:
            await self._pause_for(loop, wait)
            if self._transport is not transport:
                raise PortError(f"{self.settings.url} was lost")
        self.write_now(data, discard=True)

    def pause_left(self, now: float) -> float:
        """Seconds of the start pause still to wait at ``now`` (0 or less: none).

        The pause runs from the last byte received, or from the end on the
        wire of our own last request when nothing came back since.
        """
        return self._quiet_at + self._pause - now

    def write_now(self, data: bytes, *, discard: bool) -> None:
        """Write ``data`` at once (the caller waited out :meth:`pause_left`).

        ``discard`` drops unread input first (read and dropped, never flushed
        behind a read already due: :mod:`pkwbus.link.transport`); the caller
        asks for it only when stray input must not be taken for the answer.
        :class:`PortError` when the port is not open, and when its fence closed: then
        nothing is written and the port is given up.
        """
        transport = self._transport
        loop = self._loop
        if transport is None or loop is None or self._state is not LinkState.OPEN:
            raise PortError(f"{self.settings.url} is not open")
        if fence_closed(self.fence):
            reason = f"{self.settings.url}: {fenced_reason(self.fence)}"
            log.debug("%s", reason)  # told by the abort to the line's listeners, who log it
            self.abort(reason)
            raise PortError(reason)
        if discard:
            self._discard_input()
        if self._echo_on:
            self._echo = data
        self._write(transport, data)
        self._quiet_at = loop.time() + len(data) * self._char_time

    @property
    def fine_timers(self) -> bool:
        """Whether the loop the port was opened on times to the microsecond."""
        return self._fine

    async def _pause_for(self, loop: asyncio.AbstractEventLoop, wait: float) -> None:
        """Wait ``wait`` seconds, to the microsecond rather than to the loop's millisecond."""
        if has_fine_timers(loop):  # pkwbus's own loop waits to the microsecond
            await asyncio.sleep(wait)
            return
        coarse = math.floor(wait / LOOP_TIMER_RESOLUTION) * LOOP_TIMER_RESOLUTION
        if coarse > 0:
            end = loop.time() + wait
            await asyncio.sleep(coarse)
            wait = end - loop.time()
        if wait > 0:
            if self._fine_timer is None:
                self._fine_timer = ThreadPoolExecutor(1, thread_name_prefix="pkwbus-pause")
            await loop.run_in_executor(self._fine_timer, time.sleep, wait)

    def _write(self, transport: SerialTransport, data: bytes) -> None:
        """Write straight to the port when nothing is queued; else through the transport."""
        fd = self._fd
        if fd >= 0 and not transport.queued:
            try:
                n = os.write(fd, data)
            except (BlockingIOError, InterruptedError):
                n = 0
            except OSError as exc:  # EIO: the device is gone
                transport.lose(describe_error(exc))
                return
            if n == len(data):
                return
            data = data[n:]
        transport.write(data)

    def _discard_input(self) -> None:
        transport = self._transport
        if transport is not None:
            dropped = transport.discard_input()
            if dropped:
                log.debug("%s: %d stray bytes dropped", self.settings.url, dropped)

    def _on_data(self, data: bytes) -> None:
        loop = self._loop
        now = loop.time() if loop is not None else asyncio.get_running_loop().time()
        if self._echo:
            self._quiet_at = max(self._quiet_at, now)
            data = self._strip_echo(data)
            if not data:
                return
        # Another station's bytes: our request has left the wire, the line was busy until now.
        self._quiet_at = now
        if self._receiver is not None:
            self._receiver(data)

    def _strip_echo(self, data: bytes) -> bytes:
        """Remove the echo of our own request from the start of the input."""
        n = min(len(self._echo), len(data))
        if data[:n] != self._echo[:n]:
            log.warning("echo does not match the request sent on %s", self.settings.url)
            self._echo = b""
            return data
        self._echo = self._echo[n:]
        return data[n:]

    def _on_lost(self, protocol: _Protocol, exc: Exception | None) -> None:
        if protocol is not self._protocol:
            return  # an earlier opening's transport, closed since: not the current port
        self._transport = self._protocol = None
        self._fd = -1
        self._leave()
        if self._closing:
            return
        reason = describe_error(exc) if exc else "closed by the other end"
        self._state = LinkState.FAILED
        told = f"lost {self.settings.url}: {reason}"
        self.reconnect.failed(told, asyncio.get_running_loop().time())
        if self._on_lost_cb is not None:
            self._on_lost_cb(told)
