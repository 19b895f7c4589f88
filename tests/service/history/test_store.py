"""The history database: each entry once, by content; newest first; pruned only when the
drive's log no longer holds an entry."""

from __future__ import annotations

from pathlib import Path

import pytest
from prometheus_client import CollectorRegistry

from pkwbus.service.history.store import DriveEvent, HistoryError, HistoryStore
from pkwbus.service.history.stream import EventStream


def event(
    key: str,
    *,
    drive: str = "d1",
    time: float | None = None,
    seen: float = 100.0,
    kind: str = "fault",
) -> DriveEvent:
    source = "runtime" if time is not None else "seen"
    return DriveEvent(
        "l1", drive, key, kind, "F07801", 7801, "Motor overload", 5, time, source,
        "0 d 00:00:01.000", seen,
    )  # fmt: skip


def test_an_entry_is_stored_once_whatever_the_number_of_sweeps(tmp_path: Path) -> None:
    store = HistoryStore(tmp_path / "history.sqlite")
    assert store.add([event("a"), event("b")]) == [event("a"), event("b")]
    assert store.add([event("b"), event("c")]) == [event("c")]
    store.close()
    again = HistoryStore(tmp_path / "history.sqlite")  # a restart
    assert again.add([event("a"), event("b"), event("c")]) == []
    assert again.known("d1") == {"a", "b", "c"}
    assert again.counts() == {("l1", "d1", "fault", "F07801", "Motor overload"): 3}


def test_the_same_content_of_two_drives_is_two_entries(tmp_path: Path) -> None:
    store = HistoryStore(tmp_path / "h.sqlite")
    assert len(store.add([event("a"), event("a", drive="d2")])) == 2


def test_latest_newest_first_by_the_drives_time_else_when_seen(tmp_path: Path) -> None:
    store = HistoryStore(tmp_path / "h.sqlite")
    store.add([event("old", time=10.0, seen=500.0), event("new", time=400.0, seen=500.0),
               event("untimed", seen=300.0), event("other", drive="d2", seen=600.0)])  # fmt: skip
    assert [e.key for e in store.latest()] == ["other", "new", "untimed", "old"]
    assert [e.key for e in store.latest(drive="d1", limit=2)] == ["new", "untimed"]
    assert [e.key for e in store.latest(since=350.0)] == ["other", "new"]


def test_pruning_keeps_what_the_drives_log_still_holds(tmp_path: Path) -> None:
    store = HistoryStore(tmp_path / "h.sqlite")
    store.add([event("gone", seen=10.0), event("held", seen=10.0), event("young", seen=900.0)])
    assert store.prune("d1", ["fault"], ["held"], before=500.0) == 1
    assert store.known("d1") == {"held", "young"}
    # Found again in the drive's log: still known, so not new (never counted twice).
    assert store.add([event("held")]) == []


def test_one_logs_pruning_never_drops_another_logs_entries(tmp_path: Path) -> None:
    """A SINAMICS drive has a fault buffer and an alarm buffer: the fault buffer's sweep
    holds no alarm, and must not drop the alarms the other buffer still holds."""
    store = HistoryStore(tmp_path / "h.sqlite")
    store.add([event("fault gone", seen=10.0), event("alarm held", kind="alarm", seen=10.0)])
    assert store.prune("d1", ["fault"], [], before=500.0) == 1
    assert store.known("d1") == {"alarm held"}
    assert store.prune("d1", ["alarm"], [], before=500.0) == 1
    assert store.known("d1") == set()


def test_a_place_that_cannot_hold_the_database_is_one_clear_error(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    with pytest.raises(HistoryError, match="cannot open the history database"):
        HistoryStore(tmp_path / "file" / "history.sqlite")


async def test_the_count_at_start_is_of_the_drives_configured_now(tmp_path: Path) -> None:
    """What the history holds of a drive removed (or moved to another line) is kept, but not
    counted at the next start: its series would stand for a drive that is not there."""
    store = HistoryStore(tmp_path / "history.sqlite")
    store.add([event("a"), event("b"), event("c", drive="gone")])
    registry = CollectorRegistry()
    stream = EventStream(store, registry)
    stream.present = frozenset({("l1", "d1")})
    assert await stream.start()
    counted = {
        s.labels["drive"]: s.value
        for f in registry.collect()
        for s in f.samples
        if s.name == "pkwbus_drive_events_total"
    }
    assert counted == {"d1": 2.0}
    assert store.known("gone") == {"c"}  # kept all the same
    store.close()
