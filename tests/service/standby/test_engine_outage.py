"""Who masters a line, as an instance tells it while etcd does not answer: nobody it knows
of (what etcd named last may have expired since), against a real etcd."""

from __future__ import annotations

from pkwbus.service.standby import Master
from tests.service.standby.test_engine import a_holds_l0_b_waits
from tests.service.standby_process.etcd import Etcd

from .conftest import LEASE, Make, until


async def test_while_etcd_is_away_no_instance_is_named_master_of_another_ones_line(
    etcd: Etcd, engines: Make
) -> None:
    a, b = await a_holds_l0_b_waits(etcd, engines)
    assert b.standby.master_of("l0") == Master("a", "http://a.example:9725")
    etcd.kill(etcd.members[0])
    await until(lambda: not b.standby.etcd_up, 3 * LEASE, "b sees etcd gone")
    await until(lambda: b.standby.master_of("l0") is None, 3 * LEASE, "b names nobody")
    await until(lambda: a.standby.master_of("l0") is None, 3 * LEASE, "a no longer holds it")
    etcd.launch(etcd.members[0])
    await etcd.wait_healthy(etcd.members)
    await until(lambda: b.standby.master_of("l0") is not None, 15, "b names its master again")
