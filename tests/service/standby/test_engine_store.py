"""The hot standby engine when etcd comes back as another store: killed, its data deleted, an
empty etcd started on the same address (its revisions started anew, below those the engines
saw). Two engines in this process on the real etcd."""

from __future__ import annotations

import json
import logging

import pytest

from pkwbus.link.fence import FENCE_CLOCK
from tests.service.standby_process.etcd import Etcd

from .conftest import Engine, Make, until

LINES = ["l0", "l1"]
STORE_LEASE = 4.0
NEW_STORE = "etcd is not the store it was (revision went back from"


def held_spans(engine: Engine, line: str) -> list[tuple[float, float]]:
    """When ``engine`` told ``line`` held: (from, to) spans, the last open to infinity."""
    spans: list[tuple[float, float]] = []
    since: float | None = None
    for at, told, held in engine.told:
        if told != line:
            continue
        if held and since is None:
            since = at
        elif not held and since is not None:
            spans.append((since, at))
            since = None
    return spans if since is None else [*spans, (since, float("inf"))]


def found(caplog: pytest.LogCaptureFixture) -> list[str]:
    """What the engines logged on finding etcd another store."""
    return [
        r.getMessage()
        for r in caplog.records
        if r.getMessage().startswith("hot standby: " + NEW_STORE)
    ]


def mastered(a: Engine, b: Engine) -> bool:
    """Each line held by one of them, and both name that one its master."""
    for line in LINES:
        holders = [e for e in (a, b) if e.standby.holds(line)]
        if len(holders) != 1:
            return False
        master = holders[0].standby.me
        if not a.standby.master_of(line) == b.standby.master_of(line) == master:
            return False
    return True


async def test_etcd_back_empty_every_line_has_a_master_again_and_never_two(
    etcd: Etcd, engines: Make, caplog: pytest.LogCaptureFixture
) -> None:
    """etcd back within the fences (lease 4 s: open >= 1.7 s after the kill): the lines are
    silenced once it is found another store, and taken again after one lease."""
    caplog.set_level(logging.WARNING, logger="pkwbus.service.standby")
    for n in range(30):  # the old store well ahead of what the new one reaches soon
        await etcd.put("/elsewhere/n", str(n).encode())
    a = engines(etcd, "a", LINES, lease=STORE_LEASE)
    b = engines(etcd, "b", LINES, lease=STORE_LEASE)
    await a.standby.start()
    await until(lambda: a.held() == LINES, 10, "a holds both lines")
    await b.standby.start()
    await until(lambda: mastered(a, b) and b.held() != [], 15, "one line each, both know")
    old = {e.standby.lease.id for e in (a, b)} | {e.standby.registry.id for e in (a, b)}

    etcd.wipe(etcd.members[0])
    etcd.launch(etcd.members[0])
    launched = FENCE_CLOCK()
    await etcd.wait_healthy(etcd.members)
    assert await etcd.keys("/test/") == {}  # empty indeed
    await until(lambda: len(found(caplog)) == 2, 4 * STORE_LEASE, "both find etcd another store")
    for e in (a, b):  # silenced, whatever their fences' leases said
        assert e.held() == [] and all(e.standby.fence(n).open_until() == 0.0 for n in LINES)
    await until(lambda: mastered(a, b), 6 * STORE_LEASE, "each line mastered again, both agree")

    keys = await etcd.keys("/test/lines/")
    for line in LINES:
        holder = a if a.standby.holds(line) else b
        assert json.loads(keys[f"/test/lines/{line}"])["name"] == holder.standby.name
        # never both at once; nobody on the new store before a lease from when it answered
        a_spans, b_spans = held_spans(a, line), held_spans(b, line)
        assert all(
            end <= start2 or end2 <= start for start, end in a_spans for start2, end2 in b_spans
        )
        assert all(t < launched or t >= launched + STORE_LEASE for t, _ in a_spans + b_spans)
    # the new store knew none of the old leases: granted anew
    assert old.isdisjoint(
        {e.standby.lease.id for e in (a, b)} | {e.standby.registry.id for e in (a, b)}
    )
    assert len(found(caplog)) == 2, found(caplog)  # once by each
