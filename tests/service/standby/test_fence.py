"""The fence's arithmetic on a fake clock: no etcd."""

from __future__ import annotations

import pytest

from pkwbus.service.standby import LineLeaseFence, margin
from pkwbus.service.standby.fence import LeaseClock, renew_every, request_timeout, retry_every


class Clock:
    def __init__(self, now: float = 100.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


@pytest.mark.parametrize(("lease", "expected"), [(2, 1.0), (4, 1.0), (6, 1.5), (60, 15.0)])
def test_the_margin_is_a_quarter_of_the_lease_and_at_least_a_second(
    lease: float, expected: float
) -> None:
    assert margin(lease) == expected


@pytest.mark.parametrize("lease", [2.0, 3.0, 6.0, 10.0, 60.0])
def test_two_renewals_may_fail_before_the_fence_closes(lease: float) -> None:
    """Renewals every lease / 3; the fence open lease - margin after each, so a renewal
    and the one after it may fail, each try bounded well under what is left."""
    assert lease - margin(lease) >= renew_every(lease) * 1.5
    assert 0 < request_timeout(lease) <= lease / 4
    assert 0 < retry_every(lease) <= renew_every(lease)


def test_the_fence_is_timed_from_when_the_renewal_was_sent() -> None:
    clock = Clock()
    fence = LeaseClock(6.0, clock)
    assert fence.open_until() == 0.0 and not fence.is_open()
    fence.renewed(sent=100.0, ttl=6)
    assert fence.open_until() == 100.0 + 6.0 - 1.5
    clock.now = 103.0  # the answer arrived late: the fence does not move for that
    fence.renewed(sent=101.0, ttl=6)
    assert fence.open_until() == 101.0 + 4.5
    clock.now = 105.49
    assert fence.is_open() and fence.left() == pytest.approx(0.01)
    clock.now = 105.5
    assert not fence.is_open() and fence.left() == 0.0


def test_an_older_renewal_answered_last_never_moves_the_fence_back() -> None:
    fence = LeaseClock(6.0, Clock())
    fence.renewed(sent=110.0, ttl=6)
    fence.renewed(sent=104.0, ttl=6)
    assert fence.open_until() == 110.0 + 4.5


def test_a_ttl_longer_than_the_lease_counts_as_the_lease_and_none_closes() -> None:
    fence = LeaseClock(2.0, Clock())
    fence.renewed(sent=100.0, ttl=3)  # etcd rounds a lease up to whole seconds
    assert fence.open_until() == 100.0 + 2.0 - 1.0
    fence.renewed(sent=101.0, ttl=0)  # etcd has no such lease (any more)
    assert fence.open_until() == 0.0
    fence.renewed(sent=102.0, ttl=2)
    fence.renewed(sent=102.5, ttl=-1)
    assert fence.open_until() == 0.0 and not fence.is_open()


def test_a_lines_fence_is_its_leases_while_held_and_shut_otherwise() -> None:
    clock = Clock()
    lease = LeaseClock(4.0, clock)
    lease.renewed(sent=100.0, ttl=4)
    held: dict[str, LeaseClock] = {"l0": lease}
    fence = LineLeaseFence("l0", held.get)
    other = LineLeaseFence("l1", held.get)
    assert fence.open_until() == 103.0 and other.open_until() == 0.0
    del held["l0"]
    assert fence.open_until() == 0.0


async def test_one_clock_times_every_deadline_of_the_lease() -> None:
    """The engine's clock (by default link.fence.FENCE_CLOCK, which the port's check
    uses too) is the etcd client's, the view's and both lease keepers' fences'."""
    import inspect

    from pkwbus.link.fence import FENCE_CLOCK
    from pkwbus.service.config import StandbyConfig
    from pkwbus.service.standby import Standby

    assert inspect.signature(Standby).parameters["clock"].default is FENCE_CLOCK
    clock = Clock(500.0)
    config = StandbyConfig.model_validate(
        {"etcd": ["http://127.0.0.1:1"], "lease": "4s", "name": "a"}
    )
    engine = Standby(config, ["l1"], on_change=lambda line, held: None, clock=clock)
    try:
        assert engine.etcd.clock is clock and engine.view.clock is clock
        for keeper in (engine.lease, engine.registry):
            assert keeper.clock is clock and keeper.fence.clock is clock
        engine.lease.fence.renewed(sent=500.0, ttl=4)
        clock.now = 502.9
        assert engine.lease.fence.is_open() and engine.lease.fence.left() == pytest.approx(0.1)
        clock.now = 503.0  # sent + lease - margin, on the injected clock alone
        assert not engine.lease.fence.is_open()
    finally:
        await engine.etcd.aclose()
