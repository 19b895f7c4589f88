"""Waiting for an event with a time limit, without losing a cancellation.

``asyncio.wait_for(event.wait(), t)`` on Python 3.11 returns normally when the
task is cancelled in the same turn the event is set: the cancellation is lost,
and a loop around it (a line's idle wait, a campaign's tick) never ends, so
whoever stops it waits forever. ``asyncio.timeout`` tells its own expiry from a
cancellation from outside, so :func:`wait_event` is built on it.
"""

from __future__ import annotations

import asyncio

__all__ = ["wait_event"]


async def wait_event(event: asyncio.Event, timeout: float) -> bool:
    """True once ``event`` is set, False after ``timeout`` seconds; a cancellation
    from outside is always raised."""
    if event.is_set():
        await asyncio.sleep(0)  # a cancellation already asked for is raised here
        return True
    try:
        async with asyncio.timeout(max(0.0, timeout)):
            await event.wait()
    except TimeoutError:
        return False
    return True
