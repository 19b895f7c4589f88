"""A drive in maintenance, on a fake clock: nothing goes out to it (no poll, no job, no
probe), it is neither shown up nor down while the others go on, and out of maintenance
it is a drive that came back: polled at once, shown up at its first answer."""

from __future__ import annotations

from pkwbus.master.planning.jobs import Cancelled
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import Finished, HealthChanged, Send
from pkwbus.master.planning.planner import IN_MAINTENANCE
from pkwbus.protocol import pkw
from tests.master.planning.test_planner import fake_line, target_of


def sent_to(fake: object, drive: str, since: int = 0) -> int:
    return sum(1 for s in fake.sent[since:] if s.drive == drive)  # type: ignore[attr-defined]


def test_a_drive_in_maintenance_gets_nothing_and_the_others_go_on() -> None:
    fake = fake_line("fc", [1, 2], [1613], every=0.05)
    fake.run(0.5)
    assert sent_to(fake, "d1") and sent_to(fake, "d2")
    queued = fake.submit(
        "d1", pkw.write(target_of(fake.planner, "d1").dialect, 341, 500, pkw.Width.DWORD)
    )
    fake.planner.maintenance("d1", True, fake.now)
    fake.events.extend(fake.planner.take_events())
    (ended,) = fake.finished(queued)
    assert isinstance(ended.outcome, Cancelled) and ended.outcome.reason == IN_MAINTENANCE
    since, events_since = len(fake.sent), len(fake.events)
    later = fake.submit("d1", pkw.read(target_of(fake.planner, "d1").dialect, 1613))
    fake.run(60.0)  # long enough for probes at back-off, if any went out
    assert sent_to(fake, "d1", since) == 0, "no telegram to a drive in maintenance"
    assert sent_to(fake, "d2", since) > 100, "the rest of the line goes on"
    (refused,) = fake.finished(later)
    assert isinstance(refused.outcome, Cancelled) and refused.outcome.reason == IN_MAINTENANCE
    health = [e for e in fake.events[events_since:] if isinstance(e, HealthChanged)]
    assert not [e for e in health if e.drive == "d1"], "neither down nor up"


def test_out_of_maintenance_a_drive_is_polled_at_once_and_shown_up_at_its_answer() -> None:
    fake = fake_line("fc", [1, 2], [1613], every=10.0)
    fake.run(0.5)
    fake.planner.maintenance("d1", True, fake.now)
    fake.run(30.0)
    since, events_since = len(fake.sent), len(fake.events)
    fake.planner.maintenance("d1", False, fake.now)
    fake.run(0.2)  # well within its 10 s interval: the poll is due at once
    assert sent_to(fake, "d1", since) >= 1
    ups = [
        e for e in fake.events[events_since:]
        if isinstance(e, HealthChanged) and e.drive == "d1"
    ]  # fmt: skip
    assert [e.up for e in ups] == [True]
    polled = [
        e for e in fake.events[events_since:]
        if isinstance(e, Finished) and e.drive == "d1" and not isinstance(e.outcome, Cancelled)
    ]  # fmt: skip
    assert polled


def test_a_dead_drive_in_maintenance_is_not_probed_nor_shown_down() -> None:
    fake = fake_line("fc", [1, 2], [1613], every=0.05)
    fake.sim.drives.pop(1)  # the fitter took it out
    fake.planner.maintenance("d1", True, fake.now)
    fake.run(30.0)
    assert sent_to(fake, "d1") == 0
    assert fake.shown("d1") is True  # never shown down
    fake.planner.maintenance("d1", False, fake.now)
    fake.events.extend(fake.planner.take_events())
    fake.run(5.0)
    assert sent_to(fake, "d1") > 0 and fake.shown("d1") is False  # taken back: found gone


def test_an_exchange_out_when_maintenance_begins_counts_and_nothing_follows_it() -> None:
    fake = fake_line("fc", [1, 2], [1613], every=10.0)
    fake.run(0.5)  # both polled once: idle until their next poll
    dialect = target_of(fake.planner, "d1").dialect
    job = fake.submit("d1", pkw.write(dialect, 341, 777, pkw.Width.DWORD))
    send = fake.planner.next_action(fake.now)
    plan = fake.planner.drive("d1")
    while plan.active is not None and plan.active.read_first:  # the read before the change
        assert isinstance(send, Send)
        fake.planner.exchanged(send, fake.answer(send), fake.now)
        send = fake.planner.next_action(fake.now)
    assert isinstance(send, Send) and send.drive == "d1"  # the write is on the wire
    fake.planner.maintenance("d1", True, fake.now)
    result = fake.answer(send)  # the drive took it meanwhile
    fake.planner.exchanged(send, result, fake.now)
    fake.events.extend(fake.planner.take_events())
    (done,) = fake.finished(job)
    assert isinstance(done.outcome, Answered), "acknowledged by the drive: done, not cancelled"
    assert fake.sim.drives[1].params.value(341) == 777
    since = len(fake.sent)
    fake.run(30.0)
    assert sent_to(fake, "d1", since) == 0


def test_a_lost_port_does_not_show_a_drive_in_maintenance_down() -> None:
    fake = fake_line("fc", [1, 2], [1613], every=0.05)
    fake.run(0.2)
    fake.planner.maintenance("d1", True, fake.now)
    fake.planner.port_failed()
    changes = [e for e in fake.planner.take_events() if isinstance(e, HealthChanged)]
    assert [(e.drive, e.up) for e in changes] == [("d2", False)]
