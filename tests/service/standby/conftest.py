"""Fixtures of the hot standby engine's tests: engines made on the real etcd of
tests/service/conftest.py, each stopped at the end."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass, field

import pytest

from pkwbus.link.fence import FENCE_CLOCK
from pkwbus.service.config import StandbyConfig
from pkwbus.service.standby import Standby
from tests.service.standby_process.etcd import Etcd

# Short leases keep the tests short: the fence closes lease - 1 s after a renewal.
LEASE = 2.0


@dataclass
class Engine:
    """A Standby and what it told: (FENCE_CLOCK time, line, held) in order."""

    standby: Standby
    told: list[tuple[float, str, bool]] = field(default_factory=list)

    def held(self) -> list[str]:
        return [line for line in self.standby.lines if self.standby.holds(line)]

    def lost(self) -> list[str]:
        return [line for _, line, held in self.told if not held]


Make = Callable[..., Engine]


@pytest.fixture
async def engines() -> AsyncIterator[Make]:
    """``make(etcd, name, lines, lease=LEASE)``: an engine, not started."""
    made: list[Engine] = []

    def make(server: Etcd, name: str, lines: Sequence[str], lease: float = LEASE) -> Engine:
        config = StandbyConfig(
            etcd=server.endpoints, lease=lease, prefix="/test", name=name,
            advertise=f"http://{name}.example:9725",
        )  # fmt: skip
        told: list[tuple[float, str, bool]] = []
        standby = Standby(
            config, lines, on_change=lambda line, held: told.append((FENCE_CLOCK(), line, held))
        )
        engine = Engine(standby, told)
        made.append(engine)
        return engine

    yield make
    for engine in made:
        await engine.standby.stop()


async def until(check: Callable[[], bool], timeout: float, what: str) -> None:
    """Until ``check()``; fails saying ``what`` after ``timeout`` seconds (generous:
    the tests wait for what etcd and the engine do, never for a speed)."""
    end = FENCE_CLOCK() + timeout
    while not check():
        if FENCE_CLOCK() > end:
            raise AssertionError(f"not within {timeout} s: {what}")
        await asyncio.sleep(0.02)
