"""The line's one response timer: re-armed for each exchange's own timeout, early or late."""

from __future__ import annotations

import asyncio

from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.planning.answers import ErrorKind, Failure, Reply
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.sim import SimFaults
from tests.master.conftest import make_sim, open_port, serve


def _telegram(target: DriveTarget) -> bytes:
    return SerialCarrier(target).telegram(pkw.read(target.dialect, 1613))


async def test_a_shorter_timeout_after_a_longer_one_fires_on_time() -> None:
    sim = make_sim("fc", [1, 2], faults=SimFaults(dead=frozenset({2})))
    alive, dead = DriveTarget.create("fc", 1), DriveTarget.create("fc", 2)
    async with serve(sim, "pty") as port, open_port(port, "fc", timeout=0.05) as (line, _):
        loop = asyncio.get_running_loop()
        assert isinstance(
            await line.exchange(SerialCarrier(alive).address, _telegram(alive), timeout=2.0), Reply
        )
        t0 = loop.time()
        result = await line.exchange(SerialCarrier(dead).address, _telegram(dead), timeout=0.05)
        waited = loop.time() - t0
    assert isinstance(result, Failure) and result.kind is ErrorKind.TIMEOUT
    assert 0.05 <= waited < 1.0  # not the 2 s the timer was armed for before


async def test_a_longer_timeout_after_a_shorter_one_is_not_cut_short() -> None:
    sim = make_sim("fc", [1, 2], faults=SimFaults(dead=frozenset({2})))
    alive, dead = DriveTarget.create("fc", 1), DriveTarget.create("fc", 2)
    async with serve(sim, "pty") as port, open_port(port, "fc", timeout=0.05) as (line, _):
        loop = asyncio.get_running_loop()
        # a shorter timer armed first (long enough to be answered within on a loaded machine)
        assert isinstance(
            await line.exchange(SerialCarrier(alive).address, _telegram(alive), timeout=0.3), Reply
        )
        t0 = loop.time()
        result = await line.exchange(SerialCarrier(dead).address, _telegram(dead), timeout=1.0)
        waited = loop.time() - t0
        assert isinstance(result, Failure) and result.kind is ErrorKind.TIMEOUT
        assert waited >= 1.0
        # and back to back timeouts keep their own length: not the 1 s of the one before
        t0 = loop.time()
        await line.exchange(SerialCarrier(dead).address, _telegram(dead), timeout=0.04)
        assert 0.04 <= loop.time() - t0 < 0.5
