"""The service's event loop, watched: how late it runs its callbacks
(``pkwbus_event_loop_lag_seconds``) and which callback held it (a log line).

Every line, the HTTP API and the scrapes share one loop: a callback that holds
it delays them all. :class:`LagMonitor` wakes every :data:`LAG_PERIOD` seconds
by a loop timer and observes how much later than planned it woke. A callback
that ran :data:`SLOW_CALLBACK` seconds or longer is logged with its name
(:func:`pkwbus.link.eventloop.watch_callbacks` times each one), at most once a
minute per callback (:class:`SlowCallbacks`), with the number of times it did so
meanwhile. Neither ever raises into the loop.
"""

from __future__ import annotations

import asyncio
import logging
import time
import weakref
from collections.abc import Callable
from typing import Final

from prometheus_client import CollectorRegistry, Histogram

from pkwbus.link.eventloop import callback_name, watch_callbacks

__all__ = [
    "LAG_BUCKETS",
    "LAG_PERIOD",
    "LOG_EVERY",
    "SLOW_CALLBACK",
    "LagMonitor",
    "LoopWatch",
    "SlowCallbacks",
    "lag_histogram",
]

log = logging.getLogger("pkwbus.service.loop")

LAG_BUCKETS: Final = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0)
LAG_PERIOD: Final = 0.25  # seconds between two wakes of the monitor
SLOW_CALLBACK: Final = 0.1  # seconds: a callback that holds the loop this long is logged
LOG_EVERY: Final = 60.0  # seconds: one line per callback at most this often

_LAG: weakref.WeakKeyDictionary[CollectorRegistry, Histogram] = weakref.WeakKeyDictionary()


def lag_histogram(registry: CollectorRegistry) -> Histogram:
    """The registry's ``pkwbus_event_loop_lag_seconds``, made on first use (a registry
    takes a name once; a service may be served again on one)."""
    histogram = _LAG.get(registry)
    if histogram is None:
        histogram = _LAG[registry] = Histogram(
            "pkwbus_event_loop_lag_seconds",
            "How late the event loop ran a timer of the service's (woken every"
            f" {LAG_PERIOD:g} s): what every callback waited beyond its time",
            buckets=LAG_BUCKETS,
            registry=registry,
        )
    return histogram


class LagMonitor:
    """Wakes every ``period`` seconds by a timer of the loop and observes how much later
    than planned it woke (a timer is due while a callback runs: it waits for it)."""

    def __init__(self, observe: Callable[[float], object], period: float = LAG_PERIOD) -> None:
        self._observe = observe
        self.period = period
        self._loop: asyncio.AbstractEventLoop | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._due = 0.0
        self._failed = False

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self.stop()
        self._loop = loop
        self._arm(loop.time())

    def stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._loop = None

    def _arm(self, now: float) -> None:
        assert self._loop is not None
        self._due = now + self.period
        self._timer = self._loop.call_at(self._due, self._wake)

    def _wake(self) -> None:
        loop = self._loop
        if loop is None:
            return
        try:
            now = loop.time()
            self._observe(max(0.0, now - self._due))
            self._arm(now)
        except Exception as exc:  # never into the loop; the lag is not measured from now on
            self._timer = None
            if not self._failed:
                self._failed = True
                log.warning("the event loop's lag is not measured any more: %r", exc)


class SlowCallbacks:
    """Logs a callback that held the loop: one warning line naming it and how long it ran,
    at most one per callback every ``every`` seconds; the next line says how many times
    it did so meanwhile. A callback is named by its code (a task by its coroutine
    function: all the tasks of one count as one), so a flood of them is a line a minute.
    At most ``limit`` names are remembered."""

    def __init__(
        self,
        every: float = LOG_EVERY,
        *,
        clock: Callable[[], float] = time.monotonic,
        limit: int = 256,
    ) -> None:
        self.every = every
        self.limit = limit
        self._clock = clock
        # name of the code -> [when its last line was logged, times not logged since]
        self._last: dict[str, list[float]] = {}

    def __call__(self, handle: asyncio.Handle, held: float) -> None:
        try:
            self._report(handle, held)
        except Exception:  # a log line is not worth the loop: never into it
            log.debug("a slow callback could not be reported", exc_info=True)

    def _report(self, handle: asyncio.Handle, held: float) -> None:
        name, code = callback_name(handle)
        now = self._clock()
        last = self._last.get(code)
        if last is not None and now - last[0] < self.every:
            last[1] += 1
            return
        if last is None and len(self._last) >= self.limit:
            self._forget(now)
        self._last[code] = [now, 0]
        missed = int(last[1]) if last is not None else 0
        more = f"; {missed} more time(s) since its last line, not logged" if missed else ""
        log.warning("%s held the event loop for %.3f s%s", name, held, more)

    def _forget(self, now: float) -> None:
        """Room for another name: those whose minute is over go, then the oldest."""
        for code in [c for c, (at, _) in self._last.items() if now - at >= self.every]:
            del self._last[code]
        while len(self._last) >= self.limit:
            del self._last[next(iter(self._last))]


class LoopWatch:
    """The lag monitor and the watch of slow callbacks, from the service's start to its
    stop (:func:`pkwbus.service.assembly.serve.serve`)."""

    def __init__(
        self,
        registry: CollectorRegistry,
        *,
        period: float = LAG_PERIOD,
        slow: float = SLOW_CALLBACK,
        every: float = LOG_EVERY,
    ) -> None:
        self.histogram = lag_histogram(registry)
        self.lag = LagMonitor(self.histogram.observe, period)
        self.slow = slow
        self.callbacks = SlowCallbacks(every)
        self._unwatch: Callable[[], None] | None = None

    def start(self) -> None:
        """Watch the running loop (called on it)."""
        loop = asyncio.get_running_loop()
        self.lag.start(loop)
        self._unwatch = watch_callbacks(loop, self.slow, self.callbacks)
        if self._unwatch is None:
            log.debug("not pkwbus's event loop: callbacks that hold it are not logged")

    def stop(self) -> None:
        self.lag.stop()
        if self._unwatch is not None:
            self._unwatch()
            self._unwatch = None
