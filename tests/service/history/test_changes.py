"""The history's count of its changes (service.history.store.Changes): each drive's log
entries and settings counted once a change is stored, and only then; what the service's
settings store counts lands where the history store counts (service.assembly.history)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
from prometheus_client import CollectorRegistry

from pkwbus.service.assembly.history import Memory
from pkwbus.service.history.settings_store import SettingRow, SettingsStore
from pkwbus.service.history.store import EVENTS, SETTINGS, DriveEvent, HistoryError, HistoryStore


def event(drive: str, key: str, seen: float = 100.0, kind: str = "fault") -> DriveEvent:
    return DriveEvent("l1", drive, key, kind, "7", 7, "", None, None, "seen", "", seen)


def row(drive: str, raw: int) -> SettingRow:
    return SettingRow(drive, 100, 0, "1-00", raw, str(raw), 1.0, raw, str(raw), 1.0, "sweep")


def test_new_and_pruned_entries_count_those_stored_again_do_not(tmp_path: Path) -> None:
    store = HistoryStore(tmp_path / "history.sqlite")
    changes = store.changes
    store.add([event("d1", "a"), event("d1", "b"), event("d2", "a")])
    assert (changes.count(EVENTS, ["d1"]), changes.count(EVENTS, ["d2"])) == (1, 1)
    store.add([event("d1", "a"), event("d2", "a")])  # nothing new
    assert changes.count(EVENTS, ["d1", "d2"]) == 2
    store.add([event("d2", "b")])
    assert (changes.count(EVENTS, ["d1"]), changes.count(EVENTS, ["d2"])) == (1, 2)
    assert store.prune("d1", ["fault"], ["a", "b"], before=200.0) == 0  # still held
    assert changes.count(EVENTS, ["d1"]) == 1
    assert store.prune("d1", ["fault"], ["a"], before=200.0) == 1
    assert changes.count(EVENTS, ["d1"]) == 2
    assert changes.count(SETTINGS, ["d1", "d2"]) == 0
    store.close()


def test_settings_count_each_store_and_their_events_count_as_entries(tmp_path: Path) -> None:
    history = HistoryStore(tmp_path / "history.sqlite")
    changes = history.changes
    settings = SettingsStore(history.path, changes)
    settings.save([row("d1", 5)], [event("d1", "setting|1-00", kind="setting")])
    assert (changes.count(SETTINGS, ["d1"]), changes.count(EVENTS, ["d1"])) == (1, 1)
    settings.save([row("d1", 5)])  # the same value read again: its `seen` may move
    settings.swept("d1", "FC-302", 2.0)
    settings.forget("d2", "FC-302")
    assert (changes.count(SETTINGS, ["d1"]), changes.count(SETTINGS, ["d2"])) == (3, 1)
    assert changes.count(EVENTS, ["d1", "d2"]) == 1
    settings.close()
    with pytest.raises(HistoryError):
        settings.save([row("d1", 6)])  # closed: nothing stored, nothing counted
    assert changes.count(SETTINGS, ["d1"]) == 3
    history.close()


def test_the_services_settings_store_counts_where_the_history_does(tmp_path: Path) -> None:
    history = HistoryStore(tmp_path / "history.sqlite")
    runtime = SimpleNamespace(registry=CollectorRegistry(), history=None)
    memory = Memory(runtime, history)  # type: ignore[arg-type]
    settings = memory._store()
    settings.swept("d1", "FC-302", 1.0)
    assert history.changes.count(SETTINGS, ["d1"]) == 1
    settings.close()
    history.close()
