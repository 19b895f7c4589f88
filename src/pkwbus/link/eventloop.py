"""The event loop pkwbus runs on.

asyncio's default selector (epoll) waits in whole milliseconds, rounded up,
so a start pause of 0.33 ms (3.5 characters at 115200 baud) would last a
millisecond. select() waits to the microsecond: on a loop built on it the
link keeps sub-millisecond pauses with a plain ``asyncio.sleep``. Its limit
of 1024 file descriptors is far above what one pkwbus process uses (a port
per line, the HTTP listener and its clients, the audit database).
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


def new_event_loop() -> asyncio.AbstractEventLoop:
    return asyncio.SelectorEventLoop(selectors.SelectSelector())


def has_fine_timers(loop: asyncio.AbstractEventLoop) -> bool:
    """Whether the loop's timeouts are finer than a millisecond (a select() loop)."""
    return isinstance(getattr(loop, "_selector", None), selectors.SelectSelector)


def run(main: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run`` on :func:`new_event_loop`."""
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        return runner.run(main)
