"""pkwbus's event loop: any number of descriptors, waits to the microsecond."""

from __future__ import annotations

import asyncio
import os
import socket
import time

from pkwbus.link.eventloop import FineEpollSelector, has_fine_timers, new_event_loop


def test_descriptors_above_select_s_limit_are_watched() -> None:
    """select() raises for a descriptor >= 1024; the service's loop must not."""
    loop = new_event_loop()
    pairs: list[tuple[socket.socket, socket.socket]] = []
    try:
        while True:
            a, b = socket.socketpair()
            pairs.append((a, b))
            if b.fileno() >= 1100:
                break
        reader, writer = pairs[-1][1], pairs[-1][0]
        got = loop.create_future()
        loop.add_reader(reader.fileno(), lambda: got.set_result(reader.recv(16)))
        loop.call_soon(writer.send, b"ping")
        assert loop.run_until_complete(asyncio.wait_for(got, 5)) == b"ping"
        assert has_fine_timers(loop)
    finally:
        loop.close()
        for a, b in pairs:
            a.close()
            b.close()


def test_a_short_wait_ends_when_a_descriptor_is_ready() -> None:
    """The microsecond wait is select() on the epoll descriptor: data wakes it early."""
    selector = FineEpollSelector()
    r, w = os.pipe()
    try:
        selector.register(r, 1)
        os.write(w, b"x")
        start = time.monotonic()
        ready = selector.select(60.0)  # returns at once, not after a minute
        assert time.monotonic() - start < 30
        assert [key.fd for key, _ in ready] == [r]
        os.read(r, 1)
        assert selector.select(0.0005) == []
    finally:
        selector.close()
        os.close(r)
        os.close(w)
