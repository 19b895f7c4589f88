"""wait_event: a time-limited wait that never loses a cancellation."""

from __future__ import annotations

import asyncio

import pytest

from pkwbus.waiting import wait_event


async def test_a_cancellation_in_the_turn_the_event_is_set_is_raised() -> None:
    event = asyncio.Event()
    waiting = asyncio.create_task(wait_event(event, 60.0))
    await asyncio.sleep(0)  # the task waits on the event
    event.set()
    waiting.cancel()
    with pytest.raises(asyncio.CancelledError):
        await waiting


async def test_a_wait_on_a_set_event_yields_so_a_loop_around_it_can_be_cancelled() -> None:
    event = asyncio.Event()
    event.set()

    async def looping() -> None:
        while True:
            await wait_event(event, 60.0)

    waiting = asyncio.create_task(looping())
    await asyncio.sleep(0)
    waiting.cancel()
    with pytest.raises(asyncio.CancelledError):
        await waiting


async def test_true_when_set_false_when_the_time_is_up() -> None:
    event = asyncio.Event()
    assert await wait_event(event, 0.0) is False
    asyncio.get_running_loop().call_soon(event.set)
    assert await wait_event(event, 60.0) is True
