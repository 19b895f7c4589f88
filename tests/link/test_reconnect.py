"""The reconnect object of a line's port, on a fake clock: no port, no sleeping."""

from __future__ import annotations

from pkwbus.link import LinkState, Reconnect


def test_failures_wait_a_capped_exponential_back_off_reset_once_a_station_answered() -> None:
    r = Reconnect(0.5, 2.0)
    waits = []
    now = 100.0
    for _ in range(5):
        r.failed("cannot open /dev/ttyX: gone", now)
        waits.append(r.wait(now))
        now = r.next_attempt
    assert waits == [0.5, 1.0, 2.0, 2.0, 2.0]
    assert r.wait(now) == 0.0 and r.last_error == "cannot open /dev/ttyX: gone"
    r.opened(now)
    r.failed("lost", now + 1.0)  # lost before anything answered: the outage goes on
    assert r.wait(now + 1.0) == 2.0
    now = r.next_attempt
    r.opened(now)
    assert r.usable() == 2  # a station answered, after two openings, the second not told
    r.failed("lost", now + 1.0)
    assert r.wait(now + 1.0) == 0.5


def test_a_port_refused_or_lost_right_after_each_opening_backs_off_to_the_cap() -> None:
    """Another master on the line, or a gateway that accepts and closes: the port opens
    every time, and is given up at once. The waits double up to the cap, as for a port
    that cannot be opened, not 0.5 s each time."""
    r = Reconnect(0.5, 8.0)
    now, waits, opens = 0.0, [], []
    while now < 30.0:
        opens.append(now)
        r.opened(now)
        r.failed("another master is active", now + 0.25)
        waits.append(r.wait(now + 0.25))
        now = r.next_attempt
    assert waits == [0.5, 1.0, 2.0, 4.0, 8.0, 8.0, 8.0]
    assert len(opens) == 7  # in 30 s (without the back-off: about 43)


def test_a_port_open_for_a_quiet_minute_starts_its_back_off_afresh() -> None:
    r = Reconnect(0.5, 30.0, settled=60.0)
    r.failed("lost", 0.0)
    r.opened(0.5)
    r.failed("lost", 0.5 + 59.0)  # open for under a minute: still the same outage
    assert r.wait(59.5) == 1.0 and r.repeated
    r.opened(60.5)
    r.failed("lost", 60.5 + 60.0)  # open for a minute: a new outage, told again
    assert r.wait(120.5) == 0.5 and not r.repeated


def test_an_outage_of_openings_refused_at_once_is_told_once() -> None:
    """The listeners are told each change; ``repeated`` says which belong to an outage told
    already: after the first loss and the first opening again, none until the port is
    usable; a failure of another kind is told."""
    r = Reconnect(0.5, 30.0)
    heard: list[tuple[LinkState, bool]] = []
    r.add_listener(lambda s, e: heard.append((s, r.repeated)))
    now = 0.0
    for _ in range(4):
        r.opened(now)
        r.failed("refused", now + 0.1)
        now = r.next_attempt
    opened, failed = LinkState.OPEN, LinkState.FAILED
    assert heard == [
        (opened, False), (failed, False),  # the outage begins: told
        (opened, False), (failed, True),  # the port is back, and refused again
        (opened, True), (failed, True),
        (opened, True), (failed, True),
    ]  # fmt: skip
    r.opened(now)
    r.failed("lost", now + 0.1)  # another failure: told
    assert heard[-1] == (failed, False)
    r.opened(r.next_attempt)
    assert r.usable() == 5  # the outage took five openings, some not told: worth a line
    assert r.wait(r.next_attempt) == 0.0
    r.failed("refused", r.next_attempt + 1.0)
    assert heard[-1] == (failed, False)  # a new outage
    assert r.wait(r.next_attempt - 0.5) == 0.5


def test_a_closed_port_opens_afresh() -> None:
    r = Reconnect(0.5, 30.0)
    for at in (0.0, 1.0, 3.0):
        r.opened(at)
        r.failed("refused", at + 0.1)
    r.closed()  # a reload closed it
    r.opened(10.0)
    r.failed("refused", 10.1)
    assert r.wait(10.1) == 0.5 and not r.repeated


def test_listeners_hear_each_change_once_in_order() -> None:
    r = Reconnect()
    heard: list[tuple[str, LinkState, str | None]] = []
    remove = r.add_listener(lambda s, e: heard.append(("a", s, e)))
    r.add_listener(lambda s, e: heard.append(("b", s, e)))
    r.opened(0.0)
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
