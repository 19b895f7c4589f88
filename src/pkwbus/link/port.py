"""A serial port (device path or pyserial URL) seen as a half-duplex RS-485 link.

The link writes one request at a time after the line has been quiet for the
start pause, counted from the last byte received (or the end of its own
last request on the wire), optionally strips the echo of its own
transmission, and hands every received chunk to its owner's receiver.
:meth:`Link.send` waits out the pause and discards stale input itself; a
caller that runs its exchanges from callbacks asks :meth:`Link.pause_left`
and writes with :meth:`Link.write_now`, discarding input only when stray
bytes arrived. When the port disappears it tells its owner once
(``on_lost``); when and whether to reopen is the owner's decision
(:class:`pkwbus.link.reconnect.Reconnect`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import os
import queue
import stat
import sys
import termios
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import serial
import serial.rs485
import serial_asyncio

from pkwbus.link.eventloop import has_fine_timers
from pkwbus.link.reconnect import LinkState
from pkwbus.protocol import timing

log = logging.getLogger(__name__)

PARITIES = {"E": serial.PARITY_EVEN, "O": serial.PARITY_ODD, "N": serial.PARITY_NONE}
# On a loop with an epoll selector waits last whole milliseconds, rounded up: a
# pause of 0.3 ms would last about 1 ms. There the part of a pause below this is
# waited out by a helper thread (``time.sleep`` has microsecond resolution);
# pkwbus's own loop (link.eventloop) needs no thread.
LOOP_TIMER_RESOLUTION = 0.001


class PortError(Exception):
    """The port cannot be opened or was lost."""


@dataclass(frozen=True, slots=True)
class Rs485Mode:
    """Kernel RS-485 mode (pyserial's ``RS485Settings``): RTS levels and delays in seconds."""

    rts_level_for_tx: bool = True
    rts_level_for_rx: bool = False
    delay_before_tx: float = 0.0
    delay_before_rx: float = 0.0


@dataclass(frozen=True, slots=True)
class PortSettings:
    """How to open the port. ``pause`` None = 3.5 character times at ``baudrate``.

    The timing helpers are :mod:`pkwbus.protocol.timing`'s, for these settings.

    ``low_latency`` asks the adapter's driver to pass on received bytes at once
    (an FTDI adapter otherwise holds them up to its 16 ms latency timer); a
    driver that cannot is warned of once and the line runs anyway. ``rs485``
    puts a native UART in kernel RS-485 mode; a driver that refuses it fails
    the open.
    """

    url: str
    baudrate: int = 9600
    parity: str = "E"
    stopbits: int = 1
    pause: float | None = None
    echo: bool = False
    reopen_initial: float = 0.5
    reopen_cap: float = 30.0
    low_latency: bool = False
    rs485: Rs485Mode | None = None

    def __post_init__(self) -> None:
        timing.char_time(self.baudrate, self.parity, self.stopbits)  # ValueError when wrong

    @property
    def char_bits(self) -> int:
        """Bits per character: start, 8 data, parity, stop (11 for 8E1)."""
        return timing.char_bits(self.parity, self.stopbits)

    @property
    def char_time(self) -> float:
        return timing.char_time(self.baudrate, self.parity, self.stopbits)

    @property
    def start_pause(self) -> float:
        return timing.start_pause(self.char_time, self.pause)

    @property
    def inter_char_gap(self) -> float:
        """The default silence that ends a telegram (20 characters, at least 5 ms)."""
        return timing.inter_char_gap(self.char_time)

    def wire_time(self, nbytes: int) -> float:
        return timing.wire_time(nbytes, self.char_time)


Receiver = Callable[[bytes], None]
LostListener = Callable[[str], None]


class _Protocol(asyncio.Protocol):
    def __init__(self, link: Link) -> None:
        self._link = link

    def data_received(self, data: bytes) -> None:
        self._link._on_data(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self._link._on_lost(exc)


class Link:
    """One port. Owned by one line, which gives its callbacks once; nothing else touches it."""

    def __init__(
        self,
        settings: PortSettings,
        *,
        receiver: Receiver | None = None,
        on_lost: LostListener | None = None,
    ) -> None:
        self.settings = settings
        self._receiver = receiver
        self._on_lost_cb = on_lost
        self._transport: asyncio.Transport | None = None
        self._state = LinkState.CLOSED
        self._quiet_at = 0.0
        self._echo = b""
        self._closing = False
        self._serial: Any = None
        self._fd = -1
        self._pause = settings.start_pause
        self._char_time = settings.char_time
        self._fine_timer: ThreadPoolExecutor | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._echo_on = settings.echo
        self._fine = False

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
        try:
            instance = await loop.run_in_executor(None, _open_port, s)
        except (serial.SerialException, OSError, ValueError, termios.error) as exc:
            reason = _reason(exc).split(f"{s.url}: ", 1)[-1]
            self._state = LinkState.FAILED
            raise PortError(f"cannot open {s.url}: {reason}") from None
        self._closing = False
        _closer.start()
        self._transport = _transport(loop, self, instance)
        self._serial = instance
        self._fd = _raw_fd(instance)
        self._loop = loop
        self._fine = has_fine_timers(loop)
        self._quiet_at = loop.time()
        self._state = LinkState.OPEN

    async def close(self) -> None:
        self._closing = True
        transport, self._transport = self._transport, None
        self._serial, self._fd = None, -1
        if transport is not None:
            transport.close()
            await asyncio.sleep(0)  # let connection_lost run
        if self._fine_timer is not None:
            self._fine_timer.shutdown(wait=False)
            self._fine_timer = None
        self._state = LinkState.CLOSED

    def abort(self) -> None:
        """Give the port up at once (an unexpected error); its owner decides when to reopen."""
        transport, self._transport = self._transport, None
        self._serial, self._fd = None, -1
        self._closing = True  # connection_lost of the old transport reports nothing more
        if transport is not None:
            transport.abort()
        self._state = LinkState.FAILED

    # ------------------------------------------------------------ traffic

    async def send(self, data: bytes) -> None:
        """Write ``data`` once the line has been quiet for the start pause; drop stale input."""
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

        ``discard`` drops unread input first (a ``tcflush``): the caller asks
        for it only when stray bytes arrived. :class:`PortError` when the
        port is not open.
        """
        transport = self._transport
        loop = self._loop
        if transport is None or loop is None or self._state is not LinkState.OPEN:
            raise PortError(f"{self.settings.url} is not open")
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

    def _write(self, transport: asyncio.Transport, data: bytes) -> None:
        """Write straight to the port when nothing is queued; else through the transport."""
        fd = self._fd
        if fd >= 0 and not transport.get_write_buffer_size():
            try:
                n = os.write(fd, data)
            except (BlockingIOError, InterruptedError):
                n = 0
            except OSError:
                transport.write(data)  # the transport reports the error and closes
                return
            if n == len(data):
                return
            data = data[n:]
        transport.write(data)

    def _discard_input(self) -> None:
        port = self._serial
        if port is not None:
            # termios.error (a vanished pty: EIO) is no OSError; the write that
            # follows finds the port gone and reports it.
            with contextlib.suppress(
                serial.SerialException, OSError, NotImplementedError, termios.error
            ):
                port.reset_input_buffer()

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

    def _on_lost(self, exc: Exception | None) -> None:
        self._transport = None
        self._serial, self._fd = None, -1
        if self._closing:
            return
        reason = _reason(exc) if exc else "closed by the other end"
        self._state = LinkState.FAILED
        if self._on_lost_cb is not None:
            self._on_lost_cb(f"lost {self.settings.url}: {reason}")


# Linux device majors of pseudo-terminal followers: BSD-style (3) and Unix98 (136-143),
# from the kernel's list of devices (Documentation/admin-guide/devices.txt).
_PTY_FOLLOWER_MAJORS = frozenset({3, *range(136, 144)})


def _open_port(s: PortSettings) -> Any:
    """Open the port (blocking: run in an executor)."""
    parity = serial.PARITY_NONE if is_pty(s.url) else PARITIES[s.parity]
    port = serial.serial_for_url(
        s.url,
        baudrate=s.baudrate,
        parity=parity,
        stopbits=s.stopbits,
        bytesize=8,
        timeout=0,
        write_timeout=0,
    )
    try:
        apply_adapter_settings(port, s)
    except BaseException:
        port.close()
        raise
    return port


# Ports whose driver refused low latency: warned of once each, not at every reopen.
_low_latency_refused: set[str] = set()
_ADAPTER_ERRORS = (ValueError, OSError, AttributeError, NotImplementedError, termios.error)


def apply_adapter_settings(port: Any, s: PortSettings) -> None:
    """Kernel RS-485 mode and low latency on an open ``port``, as ``s`` asks.

    RS-485 mode refused: ``serial.SerialException`` naming the setting (the
    line would drive RTS wrongly and talk to nobody). Low latency refused (a
    pty, a ``socket://`` URL, a driver without it): one warning per port.
    """
    if s.rs485 is not None:
        mode = serial.rs485.RS485Settings(
            rts_level_for_tx=s.rs485.rts_level_for_tx,
            rts_level_for_rx=s.rs485.rts_level_for_rx,
            delay_before_tx=s.rs485.delay_before_tx,
            delay_before_rx=s.rs485.delay_before_rx,
        )
        try:
            port.rs485_mode = mode
        except _ADAPTER_ERRORS as exc:
            reason = _reason(_underlying(exc))
            raise serial.SerialException(
                f"rs485: the driver refuses kernel RS-485 mode ({reason})"
            ) from None
    if s.low_latency:
        try:
            port.set_low_latency_mode(True)
        except _ADAPTER_ERRORS as exc:
            if s.url not in _low_latency_refused:
                _low_latency_refused.add(s.url)
                reason = (
                    "it has no such setting"
                    if isinstance(exc, AttributeError)
                    else _reason(_underlying(exc))
                )
                log.warning(
                    "low_latency: %s does not take it (%s); the line runs at its own latency",
                    s.url,
                    reason,
                )
        else:
            _low_latency_refused.discard(s.url)


def is_pty(url: str) -> bool:
    """Whether ``url`` is (a link to) a Linux pseudo-terminal, such as a simulator's pty.

    A pty has no parity: the Linux pty driver clears PARENB on every
    tcsetattr, and the C library's tcsetattr reads the settings back and
    reports EINVAL when none of the requested change took effect. A client
    asking for parity E therefore succeeds only when it also changes
    something else (the first one, changing the baud rate) and every later
    one with the same settings fails. A pty is opened with parity N, the one
    it keeps; the configured parity still counts in the character time.
    Real adapters (ttyS, ttyUSB, ttyACM) and URLs get what is configured.
    """
    if not sys.platform.startswith("linux") or "://" in url:
        return False
    try:
        st = os.stat(url)
    except (OSError, ValueError):
        return False
    return stat.S_ISCHR(st.st_mode) and os.major(st.st_rdev) in _PTY_FOLLOWER_MAJORS


def _transport(loop: asyncio.AbstractEventLoop, link: Link, instance: Any) -> asyncio.Transport:
    """Wrap an open port in pyserial-asyncio's transport.

    The transport assigns ``timeout = write_timeout = 0``, which the port
    already has; pyserial would still call tcsetattr again (on a pty asked
    for a parity, an EINVAL: see :func:`is_pty`). Skip the no-op.
    """
    reconfigure = instance._reconfigure_port
    instance._reconfigure_port = lambda force_update=False: None
    try:
        transport = _SerialTransport(loop, _Protocol(link), instance)
    finally:
        instance._reconfigure_port = reconfigure
    transport.fd = _raw_fd(instance)
    _closer.wrap(instance, link.settings.url)
    return transport


class _SerialTransport(serial_asyncio.SerialTransport):  # type: ignore[misc]
    """pyserial-asyncio's transport, reading a plain descriptor with read(2).

    pyserial's ``read`` waits with ``select()``, which refuses a descriptor
    numbered 1024 or above: a port reopened while many HTTP connections are
    open could get such a number and then never be read. The event loop has
    already said that the descriptor is readable, so one ``os.read`` is all
    a read needs.
    """

    fd = -1

    def _read_ready(self) -> None:
        if self.fd < 0:
            super()._read_ready()
            return
        try:
            data = os.read(self.fd, self._max_read_size)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._close(exc=serial.SerialException(_reason(exc)))
            return
        if not data:  # end of file: the device or the gateway went away
            self._close(exc=serial.SerialException("the port was closed at its other end"))
            return
        self._protocol.data_received(data)


class _Closer:
    """Closes ports off the event loop, in one daemon thread.

    The transport closes its port from a loop callback. pyserial's
    ``socket://`` close sleeps 0.3 s ("give the server some time"), and a
    real port's close may wait for its output to drain: either would stall
    every other line. Closes are handed over through a ``SimpleQueue``,
    whose ``put`` is safe even from a finaliser (a port garbage-collected
    in the middle of other work), unlike an executor's ``submit``.
    """

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[tuple[Callable[[], None], str]] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Called from ordinary code (a port being opened), never from a finaliser."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="pkwbus-close", daemon=True)
            self._thread.start()

    def wrap(self, instance: Any, url: str) -> None:
        original: Callable[[], None] = instance.close

        def close() -> None:
            instance.close = original  # one shot: later calls (__del__) close in place
            self._queue.put((original, url))

        instance.close = close

    def _run(self) -> None:
        while True:
            close, url = self._queue.get()
            try:
                close()
            except Exception as exc:  # a failing close changes nothing: the port is gone
                log.debug("closing %s: %s", url, _reason(exc))


_closer = _Closer()


# Ports whose write() is a plain write(2) of the bytes to their descriptor.
_RAW_WRITE_MODULES = frozenset({"serial.serialposix", "serial.urlhandler.protocol_socket"})


def _raw_fd(instance: Any) -> int:
    """The descriptor to write requests to directly, or -1 to use the transport.

    Only for a POSIX serial port (device or pty) and a raw TCP socket: other
    URL handlers (rfc2217 escapes bytes, loop has no descriptor) keep their
    own write path.
    """
    if type(instance).__module__ not in _RAW_WRITE_MODULES:
        return -1
    try:
        fd = instance.fileno()
    except (AttributeError, OSError, ValueError, serial.SerialException):
        return -1
    return fd if isinstance(fd, int) else -1


def _underlying(exc: BaseException) -> BaseException:
    """The OSError that pyserial wrapped in a ValueError, whose errno says more."""
    inner = exc.__cause__ or exc.__context__
    return inner if isinstance(inner, OSError | termios.error) else exc


def _reason(exc: BaseException) -> str:
    """A short reason: the system's words for an errno, else the exception's text."""
    code = getattr(exc, "errno", None)
    if code is None and isinstance(exc, termios.error) and exc.args:
        code = exc.args[0]  # termios.error is (errno, text), without an errno attribute
    if isinstance(code, int) and code > 0:
        return os.strerror(code)
    text = str(exc).strip()
    return text or type(exc).__name__
