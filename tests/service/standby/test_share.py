"""The fair share on given states: no etcd, no clock."""

from __future__ import annotations

import pytest

from pkwbus.service.standby.share import Policy, Situation, order, share

LINES = ["l0", "l1", "l2", "l3"]
POLICY = Policy(orphan_grace=0.5, retake_after=2.0, window=30.0)


@pytest.mark.parametrize(
    ("lines", "live", "expected"),
    [(4, 1, 4), (4, 2, 2), (3, 2, 2), (4, 3, 2), (1, 3, 1), (0, 2, 0)],
)
def test_the_share_is_the_ceiling(lines: int, live: int, expected: int) -> None:
    assert share(lines, live) == expected


def test_the_order_is_a_rotation_fixed_by_the_name() -> None:
    assert sorted(order(LINES, "a")) == LINES
    assert order(LINES, "a") == order(LINES, "a")
    assert {tuple(order(LINES, n)) for n in ("a", "b", "c", "d", "e", "f")} != {tuple(LINES)}
    assert order([], "a") == []


def test_alone_it_campaigns_for_every_free_line() -> None:
    s = Situation(me="a", lines=LINES, holders={}, live={"a"}, now=10.0)
    assert sorted(POLICY.campaign(s)) == LINES
    s = Situation(me="a", lines=LINES, holders={}, live=set(), now=10.0)  # not registered yet
    assert sorted(POLICY.campaign(s)) == LINES


def test_with_two_live_it_campaigns_up_to_its_share() -> None:
    s = Situation(me="a", lines=LINES, holders={"l0": "b"}, live={"a", "b"}, now=10.0)
    assert len(POLICY.campaign(s)) == 2
    s = Situation(me="a", lines=LINES, holders={"l0": "b", "l1": "a"}, live={"a", "b"}, now=10.0)
    assert len(POLICY.campaign(s)) == 1
    mine = {"l0": "a", "l1": "a"}
    s = Situation(me="a", lines=LINES, holders=mine, live={"a", "b"}, now=10.0)
    assert POLICY.campaign(s) == []


def test_a_line_free_past_the_grace_is_an_orphan_anyone_takes() -> None:
    mine = {"l0": "a", "l1": "a"}
    s = Situation(
        me="a", lines=LINES, holders=mine, live={"a", "b"}, now=10.0,
        free_since={"l2": 9.6, "l3": 9.0},
    )  # fmt: skip
    assert POLICY.campaign(s) == ["l3"]


def test_a_line_given_away_is_not_taken_back_at_once() -> None:
    s = Situation(me="a", lines=LINES, holders={"l0": "a"}, live={"a"}, now=10.0, given={"l3": 9.0})
    assert sorted(POLICY.campaign(s)) == ["l1", "l2"]
    later = Situation(
        me="a", lines=LINES, holders={"l0": "a"}, live={"a"}, now=11.0, given={"l3": 9.0}
    )
    assert sorted(POLICY.campaign(later)) == ["l1", "l2", "l3"]


def all_of(name: str) -> dict[str, str]:
    return dict.fromkeys(LINES, name)


def test_over_its_share_it_gives_one_line_away_when_another_joined() -> None:
    s = Situation(me="a", lines=LINES, holders=all_of("a"), live={"a", "b"}, now=10.0, joined=9.0)
    assert POLICY.give_away(s) == "l3"


def test_nothing_is_given_away_without_a_recent_join() -> None:
    s = Situation(me="a", lines=LINES, holders=all_of("a"), live={"a", "b"}, now=10.0)
    assert POLICY.give_away(s) is None  # b may be dead, still registered
    s = Situation(me="a", lines=LINES, holders=all_of("a"), live={"a", "b"}, now=50.0, joined=9.0)
    assert POLICY.give_away(s) is None


def test_nothing_is_given_away_at_the_share_or_when_the_others_have_theirs() -> None:
    two = {"l0": "a", "l1": "a", "l2": "b", "l3": "b"}
    s = Situation(me="a", lines=LINES, holders=two, live={"a", "b"}, now=10.0, joined=9.0)
    assert POLICY.give_away(s) is None
    three = {"l0": "a", "l1": "a", "l2": "a", "l3": "b"}
    s = Situation(me="a", lines=LINES, holders=three, live={"a", "b", "c"}, now=10.0, joined=9.0)
    assert POLICY.give_away(s) == "l2"  # c masters none of its 2
    s = Situation(me="a", lines=["l0", "l1", "l2"], holders={"l0": "a", "l1": "a", "l2": "b"},
                  live={"a", "b"}, now=10.0, joined=9.0)  # fmt: skip
    assert POLICY.give_away(s) is None  # 2 of 3 is the share


def test_one_at_a_time_and_never_an_orphan() -> None:
    three = {"l0": "a", "l1": "a", "l2": "a"}
    s = Situation(
        me="a", lines=LINES, holders=three, live={"a", "b"}, now=10.0, joined=9.0,
        given={"l3": 9.5},
    )  # fmt: skip
    assert POLICY.give_away(s) is None  # l3 is not taken yet
    s = Situation(
        me="a", lines=LINES, holders={**three, "l3": "b"}, live={"a", "b"}, now=10.0,
        joined=9.0, given={"l3": 9.5}, orphans={"l2"},
    )  # fmt: skip
    assert POLICY.give_away(s) == "l1"
    s = Situation(
        me="a", lines=LINES, holders=all_of("a"), live={"a", "b"}, now=10.0, joined=9.0,
        orphans=set(LINES),
    )  # fmt: skip
    assert POLICY.give_away(s) is None
