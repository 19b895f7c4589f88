"""Ports are closed off the event loop, and a caller can wait for the closes handed over."""

from __future__ import annotations

import threading

from pkwbus.link.serialport import _Closer


class _SlowPort:
    def __init__(self, release: threading.Event) -> None:
        self.release = release
        self.closed = False

    def close(self) -> None:
        self.release.wait(30.0)
        self.closed = True


def test_wait_returns_once_every_close_handed_over_is_done() -> None:
    closer = _Closer()
    closer.start()
    release = threading.Event()
    ports = [_SlowPort(release) for _ in range(3)]
    for port in ports:
        closer.wrap(port, "socket://x")
        port.close()  # handed over: returns at once
    assert not any(port.closed for port in ports)
    assert not closer.wait(0.05)  # the first close still waits for its release
    release.set()
    assert closer.wait(30.0)
    assert all(port.closed for port in ports)


def test_wait_with_nothing_ever_closed_returns_at_once() -> None:
    assert _Closer().wait(0.0)
