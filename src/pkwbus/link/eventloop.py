"""The event loop pkwbus runs on.

asyncio's default selector (epoll) waits in whole milliseconds, rounded up,
so a start pause of 0.33 ms (3.5 characters at 115200 baud) would last a
millisecond. ``select()`` waits to the microsecond but cannot watch a file
descriptor numbered 1024 or above: a flood of HTTP connections would push
the service past that and stop it.

:class:`FineEpollSelector` keeps both: epoll watches every descriptor, and
a finite wait is spent in ``select()`` on the one epoll descriptor (readable
as soon as any watched descriptor is ready), which times out to the
microsecond. After it, epoll is asked without waiting, unless ``select()``
timed out: then nothing was ready, and the loop's timers are due.
"""

from __future__ import annotations

import asyncio
import select
import selectors
from collections.abc import Coroutine
from typing import Any, TypeVar

__all__ = ["FineEpollSelector", "has_fine_timers", "new_event_loop", "run"]

T = TypeVar("T")

# select() cannot take a descriptor at or above FD_SETSIZE.
_FD_SETSIZE = 1024


class FineEpollSelector(selectors.EpollSelector):
    """epoll for any number of descriptors, with waits to the microsecond."""

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if timeout is not None and timeout > 0:
            epfd = self.fileno()
            if epfd < _FD_SETSIZE:
                # EINTR is retried (PEP 475).
                if not select.select([epfd], [], [], timeout)[0]:
                    return []
                timeout = 0
        return super().select(timeout)


def new_event_loop() -> asyncio.AbstractEventLoop:
    return asyncio.SelectorEventLoop(FineEpollSelector())


def has_fine_timers(loop: asyncio.AbstractEventLoop) -> bool:
    """Whether the loop's timeouts are finer than a millisecond (pkwbus's own loop)."""
    selector = getattr(loop, "_selector", None)
    if isinstance(selector, FineEpollSelector):
        return selector.fileno() < _FD_SETSIZE
    return isinstance(selector, selectors.SelectSelector)


def run(main: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run`` on :func:`new_event_loop`."""
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        return runner.run(main)
