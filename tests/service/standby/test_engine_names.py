"""Two instances given one ``standby.name`` (a cloned machine's host name, say): said, once
by each instance that finds it out, against a real etcd; two of different names say
nothing of it."""

from __future__ import annotations

import asyncio
import logging

import pytest

from tests.service.standby_process.etcd import Etcd

from .conftest import LEASE, Make, until

SAID = "another instance registered as"


@pytest.mark.parametrize(("first", "second", "told"), [("a", "a", True), ("a", "b", False)])
async def test_two_instances_of_one_name_are_told(
    etcd: Etcd, engines: Make, caplog: pytest.LogCaptureFixture,
    first: str, second: str, told: bool,
) -> None:  # fmt: skip
    one, two = engines(etcd, first, ["l0"]), engines(etcd, second, ["l0"])
    with caplog.at_level(logging.ERROR, "pkwbus.service.standby"):
        await one.standby.start()
        await until(lambda: one.held() == ["l0"], 10, "the first holds l0")
        await two.standby.start()
        await until(lambda: two.standby.etcd_up, 10, "the second answers")
        await asyncio.sleep(2 * LEASE)  # registered, renewed, watched meanwhile
    said = [r.getMessage() for r in caplog.records if SAID in r.getMessage()]
    if not told:
        assert not said, said
        return
    # by one of them or both (each registers over the other), once each
    assert 1 <= len(said) <= 2 and len({m.rpartition("this one's ")[2] for m in said}) == len(said)
    assert all("give each instance its own standby.name" in m for m in said)
