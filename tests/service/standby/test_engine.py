"""The hot standby engine against a real etcd: two engines in this process, one etcd."""

from __future__ import annotations

import asyncio

from pkwbus.link.fence import FENCE_CLOCK
from pkwbus.service.standby import Master, margin
from tests.service.standby_process.etcd import Etcd

from .conftest import LEASE, Engine, Make, until

LINES = ["l0", "l1", "l2", "l3"]


async def a_holds_l0_b_waits(etcd: Etcd, engines: Make) -> tuple[Engine, Engine]:
    """Engines a and b for line l0, started one after the other: a holds it, b knows."""
    a = engines(etcd, "a", ["l0"])
    b = engines(etcd, "b", ["l0"])
    await a.standby.start()
    await until(lambda: a.held() == ["l0"], 10, "a holds l0")
    await b.standby.start()
    await until(lambda: b.standby.master_of("l0") is not None, 10, "b learns who masters l0")
    return a, b


async def test_exactly_one_holds_each_line_and_a_stop_hands_it_over(
    etcd: Etcd, engines: Make
) -> None:
    a, b = await a_holds_l0_b_waits(etcd, engines)
    assert b.standby.master_of("l0") == Master("a", "http://a.example:9725")
    assert a.standby.master_of("l0") == Master("a", "http://a.example:9725")
    assert a.standby.etcd_up and b.standby.etcd_up
    for _ in range(3 * int(LEASE)):  # three leases of renewals: it stays so
        assert a.held() == ["l0"] and b.held() == []
        await asyncio.sleep(1 / 3)
    assert b.told == [] and a.standby.takeovers("l0") == 1
    assert (await etcd.keys("/test/lines/"))["/test/lines/l0"].startswith(b'{"name":"a"')

    stopped = FENCE_CLOCK()
    await a.standby.stop()
    assert not a.standby.holds("l0") and a.standby.fence("l0").open_until() == 0.0
    await until(lambda: b.held() == ["l0"], 5, "b holds l0 after a stopped")
    assert b.told == [(b.told[0][0], "l0", True)] and b.standby.takeovers("l0") == 1
    assert b.told[0][0] > stopped
    assert b.standby.master_of("l0") == Master("b", "http://b.example:9725")
    assert a.told == [(a.told[0][0], "l0", True)]  # a's stop does not call on_change


async def test_alone_an_instance_takes_every_line(etcd: Etcd, engines: Make) -> None:
    a = engines(etcd, "a", LINES)
    await a.standby.start()
    await until(lambda: a.held() == LINES, 10, "a holds every line")
    assert sorted(line for _, line, held in a.told if held) == LINES
    fence = a.standby.fence("l2")
    assert FENCE_CLOCK() < fence.open_until() <= FENCE_CLOCK() + LEASE - margin(LEASE)


async def test_four_lines_spread_two_and_two(etcd: Etcd, engines: Make) -> None:
    a = engines(etcd, "a", LINES)
    b = engines(etcd, "b", LINES)
    await a.standby.start()
    await until(lambda: a.held() == LINES, 10, "a alone holds all")
    await b.standby.start()  # joins: a gives two lines away, one at a time
    await until(lambda: len(a.held()) == 2 and len(b.held()) == 2, 15, "2 and 2")
    assert set(a.held()).isdisjoint(b.held())
    # each learns who holds a line from its watch of etcd: the two views meet soon after
    await until(
        lambda: all(a.standby.master_of(n) == b.standby.master_of(n) is not None for n in LINES),
        10,
        "both know every line's master",
    )
    for line in LINES:
        holder = "a" if line in a.held() else "b"
        assert a.standby.master_of(line) == b.standby.master_of(line)
        assert a.standby.master_of(line) == Master(holder, f"http://{holder}.example:9725")
    await asyncio.sleep(LEASE)  # and stays so
    assert len(a.held()) == 2 and len(b.held()) == 2

    await b.standby.stop()  # a alone again: takes all
    await until(lambda: a.held() == LINES, 5, "a holds every line again")


async def test_a_set_of_lines_changed_gives_the_gone_ones_away(etcd: Etcd, engines: Make) -> None:
    a = engines(etcd, "a", ["l0", "l1"])
    await a.standby.start()
    await until(lambda: a.held() == ["l0", "l1"], 10, "a holds both")
    a.standby.set_lines(["l1", "l2"])
    await until(lambda: a.held() == ["l1", "l2"], 10, "a holds the new set")
    assert a.lost() == ["l0"]
    for _ in range(100):  # its key deleted after the release grace
        keys = await etcd.keys("/test/lines/")
        if "/test/lines/l0" not in keys:
            break
        await asyncio.sleep(0.1)
    assert sorted(keys) == ["/test/lines/l1", "/test/lines/l2"]


async def test_etcd_killed_the_fence_closes_within_the_lease_and_back_the_lines_are_held(
    etcd: Etcd, engines: Make
) -> None:
    a = engines(etcd, "a", ["l0", "l1"])
    await a.standby.start()
    await until(lambda: a.held() == ["l0", "l1"], 10, "a holds both")
    fence = a.standby.fence("l0")

    killed = FENCE_CLOCK()
    etcd.kill(etcd.members[0])
    await until(lambda: sorted(a.lost()) == ["l0", "l1"], 3 * LEASE, "a loses both")
    # the last renewal was sent before the kill: the port went silent lease - margin after
    assert fence.open_until() <= killed + LEASE - margin(LEASE)
    assert all(at >= fence.open_until() for at, _, held in a.told if not held)
    assert not a.standby.holds("l0") and FENCE_CLOCK() >= fence.open_until()
    assert not a.standby.etcd_up
    assert a.standby.master_of("l0") is None  # its own stale key is not mastering

    etcd.launch(etcd.members[0])
    await etcd.wait_healthy(etcd.members)
    await until(lambda: a.held() == ["l0", "l1"], 15, "a holds both again")
    assert a.standby.etcd_up
    assert a.told[-1][2] and a.told[-2][2]


async def test_etcd_unreachable_at_start_masters_nothing_until_it_answers(
    etcd: Etcd, engines: Make
) -> None:
    etcd.kill(etcd.members[0])
    a = engines(etcd, "a", ["l0"])
    await a.standby.start()  # does not raise
    await asyncio.sleep(LEASE)
    assert a.held() == [] and a.told == [] and not a.standby.etcd_up
    assert a.standby.fence("l0").open_until() == 0.0
    etcd.launch(etcd.members[0])
    await etcd.wait_healthy(etcd.members)
    await until(lambda: a.held() == ["l0"], 15, "a holds l0 once etcd answers")
    assert a.standby.etcd_up


async def test_marks_are_kept_by_the_holder_only(etcd: Etcd, engines: Make) -> None:
    a = engines(etcd, "a", ["l0"])
    b = engines(etcd, "b", ["l0"])
    await a.standby.start()
    await until(lambda: a.held() == ["l0"], 10, "a holds l0")
    await b.standby.start()
    await until(lambda: b.standby.master_of("l0") is not None, 10, "b sees a")
    assert await a.standby.marks.get("l0", "told") is None
    assert await a.standby.marks.put("l0", "told", b"\x00entry 17")
    assert await b.standby.marks.get("l0", "told") == b"\x00entry 17"
    assert not await b.standby.marks.put("l0", "told", b"entry 3")  # b does not hold l0
    assert await a.standby.marks.get("l0", "told") == b"\x00entry 17"

    await a.standby.stop()
    await until(lambda: b.held() == ["l0"], 5, "b holds l0")
    assert await b.standby.marks.get("l0", "told") == b"\x00entry 17"  # kept across the move
    assert await b.standby.marks.put("l0", "told", b"entry 18")
    assert await b.standby.marks.get("l0", "told") == b"entry 18"


async def test_a_stop_that_leaves_the_lines_lease_hands_the_line_over_at_its_expiry(
    etcd: Etcd, engines: Make
) -> None:
    """Its ports not closed yet (``revoke_lines=False``): the line's key stays until the lease
    expires, and b holds the line only after that, never while a's lease stands."""
    a, b = await a_holds_l0_b_waits(etcd, engines)
    stopped = asyncio.get_running_loop().time()
    await a.standby.stop(revoke_lines=False)
    assert not a.standby.holds("l0")
    assert "/test/lines/l0" in await etcd.keys("/test/lines/")  # a's, still
    await until(lambda: b.held() == ["l0"], 5 * LEASE, "b holds l0 once a's lease expired")
    assert asyncio.get_running_loop().time() - stopped >= LEASE - 1  # not at once
