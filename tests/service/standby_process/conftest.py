"""Fixtures of the hot standby's process tests: a real etcd (Debian's etcd-server; the tests
skip, saying so, where it is missing), the follower line, and the group of instances."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from .etcd import Etcd, EtcdError, etcd_binary
from .follower import Follower
from .group import Group

# The lease of the process tests: 2-4 s keeps them short and still far above a loaded
# machine's scheduling hiccups.
LEASE = 3.0


@pytest.fixture
async def follower() -> AsyncIterator[Follower]:
    line = Follower()
    await line.start()
    try:
        yield line
    finally:
        await line.close()


async def started_etcd(root: Path, size: int) -> Etcd:
    """A running etcd of ``size`` members. Its ports are picked free before etcd binds them:
    another test worker may take one meanwhile, so a start that fails is tried again (three
    times in all) on new ports."""
    if etcd_binary() is None:
        pytest.skip("etcd is not installed (Debian package etcd-server)")
    for attempt in range(3):
        etcd = Etcd(root / str(attempt), size)
        try:
            await etcd.start()
        except EtcdError:
            etcd.stop()
            if attempt == 2:
                raise
        except BaseException:
            etcd.stop()
            raise
        else:
            return etcd
    raise AssertionError("unreachable")


@pytest.fixture
async def etcd(tmp_path: Path) -> AsyncIterator[Etcd]:
    server = await started_etcd(tmp_path / "etcd", 1)
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
async def etcd3(tmp_path: Path) -> AsyncIterator[Etcd]:
    server = await started_etcd(tmp_path / "etcd3", 3)
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
async def group(tmp_path: Path, follower: Follower, etcd: Etcd) -> AsyncIterator[Group]:
    instances = Group(tmp_path, [follower], etcd, lease=LEASE)
    try:
        yield instances
    finally:
        await instances.stop()


@pytest.fixture
async def group3(tmp_path: Path, follower: Follower, etcd3: Etcd) -> AsyncIterator[Group]:
    instances = Group(tmp_path, [follower], etcd3, lease=LEASE)
    try:
        yield instances
    finally:
        await instances.stop()
