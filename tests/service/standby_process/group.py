"""A hot standby group as the process tests and the benchmark run it: a follower (the
line), an etcd, and `pkwbus run` instances named a, b, ... on one configuration."""

from __future__ import annotations

import asyncio
import inspect
import time
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path

from .etcd import Etcd, EtcdError
from .follower import Follower
from .instances import Instance, group_config

PREFIX = "/pkwbus-test"


class Group:
    """``followers``: one line each (l1, l2, ...); ``follower`` is the first, l1."""

    def __init__(
        self,
        tmp: Path,
        followers: Sequence[Follower],
        etcd: Etcd,
        *,
        lease: float,
        names: str = "ab",
    ) -> None:
        self.tmp = tmp
        self.followers = list(followers)
        self.follower = self.followers[0]
        for line in self.followers[1:]:
            line.owners = self.follower.owners  # one register of the instances' processes
        self.etcd = etcd
        self.lease = lease
        urls = [line.url for line in self.followers]
        self.config = group_config(tmp / "pkwbus.json", urls, etcd.endpoints, lease=lease)
        self.instances = {n: Instance(n, self.config, tmp / f"{n}.log") for n in names}

    def __getitem__(self, name: str) -> Instance:
        return self.instances[name]

    async def start(self, name: str) -> Instance:
        """Start instance ``name``; the follower knows its connections from the start."""
        instance = self.instances[name]
        await instance.start(owners=self.follower.owners)
        return instance

    async def registration(self, name: str) -> int:
        """The etcd revision that created the instance's key ({prefix}/instances/{name});
        0 while there is none."""
        entries = await self.etcd.entries(f"{PREFIX}/instances/")
        return entries.get(f"{PREFIX}/instances/{name}", (b"", 0))[1]

    async def registered(self, name: str, after: int = 0, timeout: float = 30.0) -> None:
        """Until etcd holds the instance's key, created after revision ``after`` (a restarted
        instance's, not the one its killed process left to expire): it campaigns."""

        async def anew() -> bool:
            return await self.registration(name) > after

        await self.until(f"{name} registered in etcd", timeout, anew, every=0.1)

    async def transmitting(self, name: str, since: float = 0.0, timeout: float = 30.0) -> float:
        """Until the follower gets a request from ``name`` at or after ``since``; its time."""
        await self.until(
            f"a request from {name}",
            timeout,
            lambda: self.follower.first_of(name, since) is not None,
        )
        first = self.follower.first_of(name, since)
        assert first is not None
        return first.at

    async def master_and_standby(self) -> tuple[Instance, Instance]:
        """a started first and transmitting, then b started and registered: (a, b)."""
        a = await self.start("a")
        await self.transmitting("a")
        b = await self.start("b")
        await self.registered("b")
        return a, b

    async def until(
        self,
        what: str,
        timeout: float,
        check: Callable[[], bool | Awaitable[bool]],
        *,
        every: float = 0.02,
    ) -> float:
        """Seconds until ``check()`` (awaited if it is a coroutine) holds; fails the test
        after ``timeout`` with the instances' logs."""
        start = time.monotonic()
        while True:
            try:
                ok = check()
                if inspect.isawaitable(ok):
                    ok = await ok
            except EtcdError:  # etcd away for a moment: ask again
                ok = False
            if ok:
                return time.monotonic() - start
            if time.monotonic() - start > timeout:
                raise AssertionError(f"no {what} within {timeout} s\n{self.logs()}")
            await asyncio.sleep(every)

    def logs(self) -> str:
        parts = [f"--- {n} ---\n{i.said()[-4000:]}" for n, i in self.instances.items()]
        return "\n".join(parts)

    async def stop(self) -> None:
        for instance in self.instances.values():
            await instance.kill()
