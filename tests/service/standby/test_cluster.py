"""The hot standby engine on a 3-member etcd: losing one member, the leader, keeps the
lines mastered where they are."""

from __future__ import annotations

import asyncio
import time

from tests.service.standby_process.etcd import Etcd

from .conftest import Make, until

# Longer than the other tests' lease: etcd elects a new leader within 1-2 s of its
# default election timeout (longer on a loaded machine), and the renewals must reach it
# before the fence closes (lease - margin after the last one sent: 6 s).
LEASE = 8.0


async def test_the_leader_member_killed_the_lines_stay_held(etcd3: Etcd, engines: Make) -> None:
    a = engines(etcd3, "a", ["l0", "l1"], lease=LEASE)
    b = engines(etcd3, "b", ["l0", "l1"], lease=LEASE)
    await a.standby.start()
    await until(lambda: a.held() == ["l0", "l1"], 15, "a holds both")
    await b.standby.start()
    await until(lambda: len(a.held()) == 1 and len(b.held()) == 1, 15, "one line each")
    held = {"a": a.held(), "b": b.held()}
    told = len(a.told), len(b.told)

    leader = await etcd3.leader()
    etcd3.kill(leader)
    end = time.monotonic() + LEASE + 4.0
    while time.monotonic() < end:  # through the election and a whole lease after it
        assert {"a": a.held(), "b": b.held()} == held
        await asyncio.sleep(0.05)
    assert (len(a.told), len(b.told)) == told  # no line lost, none won
    # a request may have just met the dead member or the election: up again soon
    await until(lambda: a.standby.etcd_up and b.standby.etcd_up, 15, "etcd answers both")
    new = await etcd3.leader()
    assert new is not leader
    keys = await etcd3.keys("/test/lines/")
    assert sorted(keys) == ["/test/lines/l0", "/test/lines/l1"]
