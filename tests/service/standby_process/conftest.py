"""Fixtures of the hot standby's process tests: the follower line and the group of instances
(on the real etcd of tests/service/conftest.py)."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from .etcd import Etcd
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
