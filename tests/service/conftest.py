"""Fixtures shared by the service's tests: a real etcd of one or three members on loopback
(Debian's etcd-server; the tests that need it skip, saying so, where it is missing), in a
temp folder, killed at the end."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from tests.service.standby_process.etcd import Etcd, EtcdError, etcd_binary


async def started_etcd(root: Path, size: int) -> Etcd:
    """A running etcd of ``size`` members. Its ports are picked free before etcd binds them:
    another test worker may take one meanwhile, so a start that fails is tried again (three
    times in all) on new ports."""
    if etcd_binary() is None:
        pytest.skip("etcd is not installed (Debian package etcd-server)")
    for attempt in range(3):
        server = Etcd(root / str(attempt), size)
        try:
            await server.start()
        except EtcdError:
            server.stop()
            if attempt == 2:
                raise
        except BaseException:
            server.stop()
            raise
        else:
            return server
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
