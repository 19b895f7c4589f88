"""The transport of an open port: pyserial-asyncio's, reading a plain descriptor with read(2).

pyserial's ``read`` waits with ``select()``, which refuses a descriptor
numbered 1024 or above: a port reopened while many HTTP connections are
open could get such a number and then never be read. The event loop has
already said that the descriptor is readable, so one ``os.read`` is all a
read needs.

A read that returns nothing says the gateway went away on a TCP socket
(``socket://``: the end of the stream). On a tty it says nothing by itself:
pyserial puts a port in raw mode with VMIN = 0 and VTIME = 0, where a read
returns what is there, or 0 bytes at once when nothing is (POSIX.1-2017,
General Terminal Interface, section 11.1.7 "Non-Canonical Mode Input
Processing", case D; Linux answers so even with O_NONBLOCK). A read the loop
found due comes back empty whenever the input was taken first: discarded by
the link (:meth:`SerialTransport.discard_input`) or by another program that
has the port open. A tty is lost only when the device says so:

- a read fails (EIO);
- a poll after an empty read reports a hang-up or an error: the kernel hangs
  a tty up when its USB adapter is unplugged and when the other end of a pty
  closes, and reads return 0 bytes from then on;
- it stays readable while every read finds nothing, with nothing received,
  for :data:`EMPTY_READS_LOST_AFTER` (a device gone without a hang-up).

Discards read the input and drop it rather than flush it (``tcflush``): no
end of file or error is lost with it, and a read already due finds nothing,
which is no loss.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import select
import termios
from collections.abc import Callable
from typing import Any

import serial
import serial_asyncio

from pkwbus.link.serialport import closer, describe_error, raw_fd

__all__ = [
    "DISCARD_LIMIT",
    "EMPTY_READS_LOST_AFTER",
    "EmptyReads",
    "SerialTransport",
    "wrap_transport",
]

EMPTY_READS_LOST_AFTER = 0.5
"""Seconds a tty may stay readable while every read finds nothing, before it counts as lost.

A live tty is readable only while it holds input, which the next read takes;
an adapter gone without a hang-up is readable for ever. Half a second keeps
the loss noticed within a second, even on a loop slowed by a busy machine.
"""

# Bytes a discard reads at most: the rest of a flood that never stops (a
# babbling station) is left to the reader, and the loop goes on.
DISCARD_LIMIT = 64 * 1024
_DISCARD_CHUNK = 4096

# What a poll reports of a device that is gone: hung up, failed, or closed.
_GONE = select.POLLHUP | select.POLLERR | select.POLLNVAL


class EmptyReads:
    """The current run of reads of a tty that said it was readable and gave nothing.

    Keeps no clock: each call says what time it is.
    """

    def __init__(self, lost_after: float = EMPTY_READS_LOST_AFTER) -> None:
        self.lost_after = lost_after
        self.since: float | None = None  # when the run began; None: no run

    def reset(self) -> None:
        """Input came, or the tty had none to give: no run."""
        self.since = None

    def readable_but_empty(self, now: float) -> bool:
        """One more such read at ``now``; True once the run has lasted :attr:`lost_after`."""
        if self.since is None:
            self.since = now
        return now - self.since >= self.lost_after


def wrap_transport(
    loop: asyncio.AbstractEventLoop, protocol: asyncio.Protocol, instance: Any, url: str
) -> SerialTransport:
    """Wrap an open port in the transport.

    The transport assigns ``timeout = write_timeout = 0``, which the port
    already has; pyserial would still call tcsetattr again (on a pty asked
    for a parity, an EINVAL: see :func:`pkwbus.link.serialport.is_pty`). Skip the no-op.
    """
    reconfigure = instance._reconfigure_port
    instance._reconfigure_port = lambda force_update=False: None
    try:
        transport = SerialTransport(loop, protocol, instance)
    finally:
        instance._reconfigure_port = reconfigure
    transport.fd = fd = raw_fd(instance)
    transport.tty = fd >= 0 and os.isatty(fd)
    closer.wrap(instance, url)
    return transport


class SerialTransport(serial_asyncio.SerialTransport):  # type: ignore[misc]
    """pyserial-asyncio's transport: reads with read(2), a port lost only when it is lost."""

    fd = -1  # the descriptor read directly; -1: pyserial's read (rfc2217, loop)
    tty = False  # an empty read is no end of file (see the module's text)

    def __init__(
        self, loop: asyncio.AbstractEventLoop, protocol: asyncio.Protocol, instance: Any
    ) -> None:
        super().__init__(loop, protocol, instance)
        self.empty_reads = EmptyReads()
        self.clock: Callable[[], float] = loop.time

    def _read_ready(self) -> None:
        if self.fd < 0:
            super()._read_ready()  # pyserial's read: nothing read is not an end there
            return
        try:
            data = self._read(self._max_read_size)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:  # EIO: the device is gone
            self.lose(describe_error(exc))
            return
        if data:
            self.empty_reads.reset()
            self._protocol.data_received(data)
        elif self.tty:
            self._empty_read()
        else:  # the end of a TCP stream: the gateway went away
            self.lose("the port was closed at its other end")

    def _read(self, size: int) -> bytes:
        return os.read(self.fd, size)

    @property
    def queued(self) -> bool:
        """Whether bytes wait to be written (what ``get_write_buffer_size`` sums up)."""
        return bool(self._write_buffer)

    def _empty_read(self) -> None:
        """A tty gave nothing: ask it whether it is still there."""
        events = self._poll()
        if events & _GONE:
            self.lose("the device hung up (unplugged, or the other end closed)")
        elif not events & select.POLLIN:
            self.empty_reads.reset()  # the input was taken before the read
        elif self.empty_reads.readable_but_empty(self.clock()):
            self.lose(
                f"the port stayed readable but gave nothing for {self.empty_reads.lost_after:g} s"
            )

    def _poll(self) -> int:
        """The tty's poll events now (without waiting)."""
        poller = select.poll()
        poller.register(self.fd, select.POLLIN)
        try:
            ready = poller.poll(0)
        except OSError:  # the descriptor is no more
            return select.POLLNVAL
        return ready[0][1] if ready else 0

    def discard_input(self) -> int:
        """Drop the input not read yet; the number of bytes dropped (0 when not known).

        The input is read and dropped here, so a read the loop already found
        due finds nothing, which is no loss. An end of file or an error is
        left to the reader, which finds it at its next read.
        """
        if self.fd < 0:
            with contextlib.suppress(
                serial.SerialException, OSError, NotImplementedError, termios.error
            ):
                self._serial.reset_input_buffer()
            return 0
        dropped = 0
        while dropped < DISCARD_LIMIT:
            try:
                data = self._read(_DISCARD_CHUNK)
            except OSError:  # EAGAIN: nothing more; an error: left to the reader
                break
            if not data:
                break
            dropped += len(data)
        if dropped:
            self.empty_reads.reset()
        return dropped

    def lose(self, reason: str) -> None:
        """The port is gone: stop reading and writing, and tell the protocol once."""
        if self._loop is None or (self._closing and not self._has_writer):
            return  # connection_lost has run or is on its way
        self._abort(serial.SerialException(reason))

    def _fatal_error(self, exc: BaseException, message: str = "") -> None:
        """A write failed: the port is lost, told to the protocol (no traceback in the log)."""
        self.lose(describe_error(exc))
