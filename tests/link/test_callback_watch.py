"""A callback that holds pkwbus's event loop is told, with its name and how long it ran
(``watch_callbacks``); the time the loop waits is no callback's."""

from __future__ import annotations

import asyncio
import functools
import time
from collections.abc import Callable, Iterator

import pytest

from pkwbus.link import eventloop
from pkwbus.link.eventloop import callback_name, watch_callbacks

Told = list[tuple[str, float]]


def blocker() -> None:
    time.sleep(0.15)


async def hog() -> None:
    await asyncio.sleep(0)
    time.sleep(0.15)


async def idle() -> None:
    await asyncio.sleep(0)


@pytest.fixture
def told() -> Iterator[tuple[Told, Callable[[asyncio.Handle, float], None]]]:
    seen: Told = []

    def report(handle: asyncio.Handle, held: float) -> None:
        seen.append((callback_name(handle)[0], held))

    yield seen, report


class Clock:
    """The watch's clock: it moves only when a callback says so, and by ``waits`` at each
    wait of the loop (a wait counted as a callback's would show at once)."""

    def __init__(self, waits: float = 10.0) -> None:
        self.now = 1000.0
        self.waits = waits

    def __call__(self) -> float:
        return self.now


async def test_a_callback_that_holds_the_loop_is_told_with_its_name_and_time(
    told: tuple[Told, Callable[[asyncio.Handle, float], None]],
) -> None:
    seen, report = told
    loop = asyncio.get_running_loop()
    unwatch = watch_callbacks(loop, 0.1, report)
    assert unwatch is not None
    try:
        loop.call_soon(blocker)
        await asyncio.sleep(0.01)  # resumed after the blocker's turn: it was told then
        await asyncio.create_task(hog(), name="hogger")
        await asyncio.sleep(0.01)
    finally:
        unwatch()
    mine = [(name, held) for name, held in seen if "blocker" in name or "hog" in name]
    assert [name for name, _ in mine] == [f"{__name__}.blocker", "task 'hogger' (hog)"]
    assert all(held >= 0.1 for _, held in mine)  # each slept 0.15 s


async def test_the_time_the_loop_waits_is_no_callbacks(
    told: tuple[Told, Callable[[asyncio.Handle, float], None]],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    seen, report = told
    clock = Clock()
    monkeypatch.setattr(eventloop, "_clock", clock)
    loop = asyncio.get_running_loop()
    selector = loop._selector  # type: ignore[attr-defined]
    waiting = selector.select

    def select(timeout: float | None = None) -> object:
        found = waiting(timeout)
        clock.now += clock.waits
        return found

    monkeypatch.setattr(selector, "select", select)

    def held_for(seconds: float) -> Callable[[], None]:
        def callback() -> None:
            clock.now += seconds

        return callback

    unwatch = watch_callbacks(loop, 0.1, report)
    assert unwatch is not None
    try:
        loop.call_soon(held_for(0.15))  # not the last of its turn
        loop.call_soon(held_for(0.05))
        await asyncio.sleep(0.05)
        loop.call_soon(held_for(0.2))  # the last of its turn: then the loop waits
        await asyncio.sleep(0.05)
    finally:
        unwatch()
    assert [round(held, 6) for name, held in seen] == [0.15, 0.2]
    assert all("held_for.<locals>.callback" in name for name, _ in seen)


async def test_a_report_that_raises_never_reaches_the_loop(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = Clock()
    monkeypatch.setattr(eventloop, "_clock", clock)
    loop = asyncio.get_running_loop()
    errors: list[dict[str, object]] = []
    loop.set_exception_handler(lambda _, context: errors.append(context))
    calls: list[float] = []

    def report(handle: asyncio.Handle, held: float) -> None:
        calls.append(held)
        raise RuntimeError("a broken report")

    def slow() -> None:
        clock.now += 1.0

    unwatch = watch_callbacks(loop, 0.1, report)
    assert unwatch is not None
    try:
        loop.call_soon(slow)
        await asyncio.sleep(0.01)
        loop.call_soon(slow)
        await asyncio.sleep(0.01)
    finally:
        unwatch()
        loop.set_exception_handler(None)
    assert calls == [1.0, 1.0] and errors == []


async def test_an_ended_watch_tells_nothing_and_the_loop_runs_on(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = Clock()
    monkeypatch.setattr(eventloop, "_clock", clock)
    loop = asyncio.get_running_loop()
    calls: list[float] = []
    ran: list[str] = []

    def slow() -> None:
        clock.now += 1.0
        ran.append("slow")

    loop.call_soon(ran.append, "queued before the watch")
    unwatch = watch_callbacks(loop, 0.1, lambda handle, held: calls.append(held))
    assert unwatch is not None
    unwatch()
    unwatch()  # twice: nothing more
    loop.call_soon(slow)
    await asyncio.sleep(0.01)
    assert calls == [] and ran == ["queued before the watch", "slow"]


def test_a_loop_that_is_not_pkwbuss_is_not_watched() -> None:
    loop = asyncio.SelectorEventLoop()
    try:
        assert watch_callbacks(loop, 0.1, lambda handle, held: None) is None
    finally:
        loop.close()


def test_the_time_between_two_runs_of_the_loop_is_no_callbacks(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = Clock(waits=0.0)
    monkeypatch.setattr(eventloop, "_clock", clock)
    loop = eventloop.new_event_loop()
    calls: list[float] = []
    try:
        assert watch_callbacks(loop, 0.1, lambda handle, held: calls.append(held)) is not None
        loop.run_until_complete(asyncio.sleep(0))
        clock.now += 60.0  # the loop does not run meanwhile
        loop.run_until_complete(asyncio.sleep(0))
    finally:
        loop.close()
    assert calls == []


class Port:
    def read_ready(self, data: bytes) -> None: ...


async def test_callbacks_are_named_by_their_code() -> None:
    loop = asyncio.get_running_loop()

    def name(callback: Callable[..., object], *args: object) -> tuple[str, str]:
        handle = loop.call_soon(callback, *args)
        try:
            return callback_name(handle)
        finally:
            handle.cancel()

    assert name(blocker) == (f"{__name__}.blocker", f"{__name__}.blocker")
    assert name(functools.partial(blocker)) == name(blocker)
    assert name(Port().read_ready, b"") == (f"{__name__}.Port.read_ready",) * 2
    assert name(loop.create_future().set_result, 1)[0].endswith("Future.set_result")
    task = asyncio.create_task(idle(), name="one")
    other = asyncio.create_task(idle(), name="other")
    await asyncio.sleep(0)  # their first steps ran: their next ones wait in the queue
    queued: list[asyncio.Handle] = list(loop._ready)  # type: ignore[attr-defined]
    mine = [h for h in queued if getattr(h._callback, "__self__", None) in (task, other)]  # type: ignore[attr-defined]
    names = sorted(callback_name(h) for h in mine)
    assert names == [("task 'one' (idle)", "idle"), ("task 'other' (idle)", "idle")]
    await asyncio.gather(task, other)
