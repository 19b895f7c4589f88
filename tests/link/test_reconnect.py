"""The reconnect object of a line's port, on a fake clock: no port, no sleeping."""

from __future__ import annotations

from pkwbus.link import LinkState, Reconnect


def test_failures_wait_a_capped_exponential_back_off_reset_on_open() -> None:
    r = Reconnect(0.5, 2.0)
    waits = []
    now = 100.0
    for _ in range(5):
        r.failed("cannot open /dev/ttyX: gone", now)
        waits.append(r.wait(now))
        now = r.next_attempt
    assert waits == [0.5, 1.0, 2.0, 2.0, 2.0]
    assert r.wait(now) == 0.0 and r.last_error == "cannot open /dev/ttyX: gone"
    r.opened()
    r.failed("lost", now)
    assert r.wait(now) == 0.5


def test_listeners_hear_each_change_once_in_order() -> None:
    r = Reconnect()
    heard: list[tuple[str, LinkState, str | None]] = []
    remove = r.add_listener(lambda s, e: heard.append(("a", s, e)))
    r.add_listener(lambda s, e: heard.append(("b", s, e)))
    r.opened()
    r.failed("lost", 1.0)
    r.failed("cannot open", 2.0)  # still failed: no change to tell
    remove()
    r.closed()
    assert heard == [
        ("a", LinkState.OPEN, None),
        ("b", LinkState.OPEN, None),
        ("a", LinkState.FAILED, "lost"),
        ("b", LinkState.FAILED, "lost"),
        ("b", LinkState.CLOSED, None),
    ]
    assert r.state is LinkState.CLOSED
