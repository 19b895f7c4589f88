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

A callback that holds the loop (:func:`watch_callbacks`): asyncio runs every
callback of a turn by taking it from the front of its queue of ready ones
(``popleft``), one after the other, then waits in the selector. So the time
from one ``popleft`` to the next is one callback's run, and the time from the
last one to the selector's wait the last one's. pkwbus's loop keeps that
queue in a :class:`collections.deque` of its own kind, which a watch turns,
in place, into one that reads the clock at each ``popleft``: one clock read
and a comparison per callback, about 0.1 µs (``bench/loop_watch.py``); while
not watched, one attribute test per turn. asyncio's debug mode
(``slow_callback_duration``) tells the same at some 14 µs per callback, the
cost of everything else debug mode does.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import functools
import math
import select
import selectors
import time
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

__all__ = [
    "FineEpollSelector",
    "SlowCallback",
    "callback_name",
    "has_fine_timers",
    "new_event_loop",
    "run",
    "watch_callbacks",
]

T = TypeVar("T")

# select() cannot take a descriptor at or above FD_SETSIZE.
_FD_SETSIZE = 1024

# What a watch tells of a callback that held the loop: its handle, and for how long (s).
SlowCallback = Callable[[asyncio.Handle, float], object]

_clock = time.perf_counter  # what a watch times callbacks by


class FineEpollSelector(selectors.EpollSelector):
    """epoll for any number of descriptors, with waits to the microsecond."""

    # Called before each wait while the loop's callbacks are watched: the last one ended.
    settle: Callable[[], None] | None = None

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        settle = self.settle
        if settle is not None:
            settle()
        if timeout is not None and timeout > 0:
            epfd = self.fileno()
            if epfd < _FD_SETSIZE:
                # EINTR is retried (PEP 475).
                if not select.select([epfd], [], [], timeout)[0]:
                    return []
                timeout = 0
        return super().select(timeout)


class _Ready(collections.deque[Any]):
    """The loop's queue of callbacks ready to run, a deque as asyncio keeps it, with room
    for a watch: :func:`watch_callbacks` makes it a :class:`_TimedReady` in place (the
    same object: a callback another thread queues meanwhile is never lost)."""

    __slots__ = ("_handle", "_report", "_since", "_threshold")
    _handle: asyncio.Handle | None  # the callback taken last, while watched
    _since: float  # when it was taken (_clock); inf: none runs
    _threshold: float
    _report: SlowCallback | None


class _TimedReady(_Ready):
    """The queue, timing each callback from its ``popleft`` to the next one's (or to the
    loop's next wait)."""

    __slots__ = ()

    def popleft(
        self, _popleft: Callable[[collections.deque[Any]], Any] = collections.deque.popleft
    ) -> Any:
        now = _clock()
        if now - self._since >= self._threshold:
            self._overran(now)
        handle = self._handle = _popleft(self)
        self._since = now
        return handle

    def settle(self) -> None:
        """The callback taken last has ended: the loop waits, or stops."""
        now = _clock()
        if now - self._since >= self._threshold:
            self._overran(now)
        self._handle, self._since = None, math.inf

    def _overran(self, now: float) -> None:
        handle, held, report = self._handle, now - self._since, self._report
        self._handle, self._since = None, math.inf
        if handle is not None and report is not None:
            with contextlib.suppress(Exception):  # a report must never stop the loop
                report(handle, held)


class _Loop(asyncio.SelectorEventLoop):
    """asyncio's selector loop, whose queue of ready callbacks can be watched."""

    def __init__(self, selector: selectors.BaseSelector | None = None) -> None:
        super().__init__(selector)
        self._ready: collections.deque[Any] = _Ready(self._ready)

    def run_forever(self) -> None:
        try:
            super().run_forever()
        finally:  # the time until the loop runs again is no callback's
            if isinstance(self._ready, _TimedReady):
                self._ready.settle()


def new_event_loop() -> asyncio.AbstractEventLoop:
    return _Loop(FineEpollSelector())


def has_fine_timers(loop: asyncio.AbstractEventLoop) -> bool:
    """Whether the loop's timeouts are finer than a millisecond (pkwbus's own loop)."""
    selector = getattr(loop, "_selector", None)
    if isinstance(selector, FineEpollSelector):
        return selector.fileno() < _FD_SETSIZE
    return isinstance(selector, selectors.SelectSelector)


def watch_callbacks(
    loop: asyncio.AbstractEventLoop, threshold: float, report: SlowCallback
) -> Callable[[], None] | None:
    """Tell ``report`` each callback of ``loop`` that ran ``threshold`` seconds or longer,
    with how long it ran; call it on the loop's thread. Returns what ends the watch; None
    when ``loop`` is not one of :func:`new_event_loop` (nothing is watched). A report
    that raises is ignored: it never reaches the loop. A second watch replaces the first."""
    ready = getattr(loop, "_ready", None)
    selector = getattr(loop, "_selector", None)
    if not isinstance(ready, _Ready) or not isinstance(selector, FineEpollSelector):
        return None
    if isinstance(ready, _TimedReady):
        ready.settle()
    ready._handle, ready._since = None, math.inf
    ready._threshold, ready._report = threshold, report
    _retype(ready, _TimedReady)
    timed = ready
    assert isinstance(timed, _TimedReady)
    selector.settle = timed.settle

    def unwatch() -> None:
        if type(ready) is _TimedReady and ready._report is report:
            timed.settle()
            selector.settle = None
            ready._report = None
            _retype(ready, _Ready)

    return unwatch


def _retype(queue: _Ready, kind: type[_Ready]) -> None:
    """The loop's queue, watched or not: its class changes, never the object."""
    queue.__class__ = kind


def callback_name(handle: asyncio.Handle | None) -> tuple[str, str]:
    """How a log line names the callback of ``handle``, and the name of its code (the same
    for every task of one coroutine function): ``task 'line l1' (LineRunner.run)`` and
    ``LineRunner.run`` for a step of a task, ``pkwbus.x.Port._read_ready`` for a function
    or method."""
    callback: Any = getattr(handle, "_callback", None)
    owner = getattr(callback, "__self__", None)
    if isinstance(owner, asyncio.Task):  # a task's step or wake-up
        coro = owner.get_coro()
        code = getattr(coro, "__qualname__", None) or type(coro).__qualname__
        return f"task {owner.get_name()!r} ({code})", code
    while isinstance(callback, functools.partial):
        callback = callback.func
    if callback is None:
        text = repr(handle)
        return text, text
    qualname = getattr(callback, "__qualname__", None) or type(callback).__qualname__
    module = getattr(callback, "__module__", None) or getattr(type(owner), "__module__", None)
    name = f"{module}.{qualname}" if module and module != "builtins" else qualname
    return name, name


def run(main: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run`` on :func:`new_event_loop`."""
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        return runner.run(main)
