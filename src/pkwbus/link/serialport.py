"""Opening and closing a serial port with pyserial.

Blocking opens run in an executor; closes go to one thread of their own
(:class:`_Closer`); the transport around an open port is
:mod:`pkwbus.link.transport`. Ptys are opened with parity N (:func:`is_pty`).

Raises: :class:`serial.SerialException`, :class:`OSError` or
:class:`ValueError` from :func:`open_port` when the port cannot be opened
or refuses RS-485 mode.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import fcntl
import logging
import os
import queue
import stat
import sys
import termios
import threading
from collections.abc import Callable
from typing import Any

import serial
import serial.rs485

from pkwbus.link.ownership import PortBusy, holders
from pkwbus.link.settings import PARITIES, PortSettings

__all__ = [
    "apply_adapter_settings",
    "closer",
    "closes_done",
    "describe_error",
    "is_pty",
    "open_port",
    "raw_fd",
    "release",
]  # fmt: skip

log = logging.getLogger(__name__)


# Linux device majors of pseudo-terminal followers: BSD-style (3) and Unix98 (136-143),
# from the kernel's list of devices (Documentation/admin-guide/devices.txt).
_PTY_FOLLOWER_MAJORS = frozenset({3, *range(136, 144)})


def open_port(s: PortSettings) -> Any:
    """Open the port (blocking: run in an executor); a device exclusively, so that no
    second master opens it (:class:`~pkwbus.link.ownership.PortBusy` when one holds it)."""
    try:
        port = _open(s)
    except serial.SerialException as exc:
        if exc.errno not in _LOCKED:
            raise
        # This process's own port, lost and closing in the closer's thread, may hold it
        # still: once every close handed over is done, once more.
        if not closer.wait(_OWN_CLOSE_WAIT):
            raise _busy(s.url) from None
        try:
            port = _open(s)
        except serial.SerialException as again:
            if again.errno in _LOCKED:
                raise _busy(s.url) from None
            raise
    try:
        apply_adapter_settings(port, s)
    except BaseException:
        port.close()
        raise
    return port


# A lock another open of the device holds (flock with LOCK_NB).
_LOCKED = frozenset({errno.EWOULDBLOCK, errno.EAGAIN})
_OWN_CLOSE_WAIT = 2.0  # seconds for this process's own closes before a port counts as busy


def _open(s: PortSettings) -> Any:
    device = "://" not in s.url  # a URL's far end decides who may connect
    parity = serial.PARITY_NONE if is_pty(s.url) else PARITIES[s.parity]
    return serial.serial_for_url(
        s.url,
        baudrate=s.baudrate,
        parity=parity,
        stopbits=s.stopbits,
        bytesize=8,
        timeout=0,
        write_timeout=0,
        exclusive=True if device else None,
    )


def release(instance: Any) -> None:
    """Give up the lock of a device opened exclusively (its descriptor may stay open a
    while: a close writes out what it holds first)."""
    fd = getattr(instance, "fd", None)
    if type(instance).__module__ != "serial.serialposix" or not isinstance(fd, int):
        return
    if getattr(instance, "exclusive", None):
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_UN)


def _busy(url: str) -> PortBusy:
    held = holders(url)
    by = f" ({'; '.join(held)})" if held else ""
    return PortBusy(
        f"{url}: in use by another process{by}: it would be a second master on the line;"
        " nothing was sent"
    )


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
            reason = describe_error(_underlying(exc))
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
                    else describe_error(_underlying(exc))
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

    def wait(self, timeout: float) -> bool:
        """Block until every close handed over so far is done; False after ``timeout`` s.

        Their descriptors are free then, and no later close of theirs can free one.
        """
        if self._thread is None:
            return True
        done = threading.Event()
        self._queue.put((done.set, "(wait)"))
        return done.wait(timeout)

    def _run(self) -> None:
        while True:
            close, url = self._queue.get()
            try:
                close()
            except Exception as exc:  # a failing close changes nothing: the port is gone
                log.debug("closing %s: %s", url, describe_error(exc))


closer = _Closer()


async def closes_done(timeout: float) -> bool:
    """Whether every port close handed over so far is done within ``timeout`` s (waited in a
    thread): a device's output drained by then and its descriptor closed, a TCP connection
    closed; False when one still runs."""
    return await asyncio.to_thread(closer.wait, timeout)


# Ports whose write() is a plain write(2) of the bytes to their descriptor.
_RAW_WRITE_MODULES = frozenset({"serial.serialposix", "serial.urlhandler.protocol_socket"})


def raw_fd(instance: Any) -> int:
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


def describe_error(exc: BaseException) -> str:
    """A short reason: the system's words for an errno, else the exception's text."""
    code = getattr(exc, "errno", None)
    if code is None and isinstance(exc, termios.error) and exc.args:
        code = exc.args[0]  # termios.error is (errno, text), without an errno attribute
    if isinstance(code, int) and code > 0:
        return os.strerror(code)
    text = str(exc).strip()
    return text or type(exc).__name__
