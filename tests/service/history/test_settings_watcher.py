"""The settings watcher's bookkeeping, without a line: a change is told once and only once
it is stored (a history database that fails leaves everything as it was, and the next
sweep tells it); an audited write moves the baseline even when the history cannot store
it, and never raises into the write; a write whose answer got lost is pkwbus's when a
sweep finds its value; a flag of a setting no longer swept is not exported; a negative
factory value reads as the drive sent it; another model starts a new baseline, other
software on the same model keeps it."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import pytest
from prometheus_client import CollectorRegistry

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.target import DriveTarget
from pkwbus.protocol.values import ParameterRef, Scaling, ValueType
from pkwbus.service.history import settings_view
from pkwbus.service.history.setting_reads import Swept
from pkwbus.service.history.settings import KIND, SettingsWatcher
from pkwbus.service.history.settings_store import SettingsStore
from pkwbus.service.history.store import HistoryError, HistoryStore
from pkwbus.service.history.stream import EventStream
from pkwbus.service.runtime import DriveEntry

RAMP = ParameterRef(341, None, "3-41")
FMT = ParameterDescription("Ramp 1 Ramp Up Time", ValueType.U32, Scaling.conversion(-2), "s")


class Failing(SettingsStore):
    """A settings store whose next ``fail`` saves raise, as a full disk would."""

    fail = 0

    def save(self, rows: Any, events: Any = ()) -> Any:
        if self.fail:
            self.fail -= 1
            raise HistoryError("history database: disk I/O error")
        return super().save(rows, events)


def made(tmp_path: Path, refs: list[ParameterRef] | None = None) -> tuple[SettingsWatcher, Swept]:
    registry = CollectorRegistry()
    history = HistoryStore(tmp_path / "history.sqlite")
    store = Failing(tmp_path / "history.sqlite")
    entry = DriveEntry("fan", "l1", DriveTarget.create("fc", 1))
    swept = Swept("l1", entry, 60.0, refs or [RAMP], "danfoss-fc")
    watcher = SettingsWatcher({}, store, EventStream(history, registry), [swept], registry)
    return watcher, swept


def flagged(w: SettingsWatcher) -> list[dict[str, str]]:
    return [s.labels for f in w.changed.collect() for s in f.samples]


def told(w: SettingsWatcher) -> list[Any]:
    return [e for e in w.stream.store.latest(drive="fan") if e.kind == KIND]


async def test_a_change_is_told_once_and_only_once_it_is_stored(tmp_path: Path) -> None:
    w, s = made(tmp_path)
    await w._compare(s, RAMP, FMT, 500, 5.0)  # the baseline
    store = w.store
    assert isinstance(store, Failing)
    store.fail = 1
    with pytest.raises(HistoryError):
        await w._compare(s, RAMP, FMT, 900, 9.0)
    assert s.rows[(341, 0)].raw == 500 and flagged(w) == [] and told(w) == []
    await w._compare(s, RAMP, FMT, 900, 9.0)  # the next sweep
    await w._compare(s, RAMP, FMT, 900, 9.0)
    assert [e.value for e in told(w)] == [900]
    assert [f["parameter"] for f in flagged(w)] == ["3-41"]


async def test_an_audited_write_moves_the_baseline_though_the_history_fails(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    w, s = made(tmp_path)
    await w._compare(s, RAMP, FMT, 500, 5.0)
    await w._compare(s, RAMP, FMT, 700, 7.0)  # a keypad change: flagged
    assert flagged(w)
    store = w.store
    assert isinstance(store, Failing)
    store.fail = 1
    with caplog.at_level(logging.ERROR):
        await w.written("fan", 341, 0, 600, 6.0)  # never raises into the write
    assert "not stored" in caplog.text
    assert flagged(w) == [] and s.rows[(341, 0)].baseline_raw == 600
    await w._compare(s, RAMP, FMT, 600, 6.0)
    assert s.rows[(341, 0)].baseline_by == "write" and told(w)[0].value == 700


async def test_a_write_whose_answer_was_lost_is_pkwbuss_when_a_sweep_finds_it(
    tmp_path: Path,
) -> None:
    w, s = made(tmp_path)
    await w._compare(s, RAMP, FMT, 500, 5.0)
    await w.written("fan", 341, 0, 650, 6.5, answered=False)
    assert s.rows[(341, 0)].baseline_raw == 500, "not before it is seen"
    await w._compare(s, RAMP, FMT, 650, 6.5)
    row = s.rows[(341, 0)]
    assert (row.baseline_raw, row.baseline_by, row.changed_seen) == (650, "write", None)
    assert flagged(w) == [] and told(w) == []
    await w._compare(s, RAMP, FMT, 660, 6.6)  # a later change is nobody's
    assert [e.value for e in told(w)] == [660]


async def test_a_flag_of_a_setting_no_longer_swept_is_not_exported(tmp_path: Path) -> None:
    w, s = made(tmp_path)
    await w._compare(s, RAMP, FMT, 500, 5.0)
    await w._compare(s, RAMP, FMT, 800, 8.0)
    other = ParameterRef(342, None, "3-42")
    again, s2 = made(tmp_path / "again", [other])
    s2.rows = dict(s.rows)  # as kept in the history, from before the configuration changed
    again._show(s2)
    assert flagged(again) == []


def test_a_negative_factory_value_reads_as_the_drive_sent_it(tmp_path: Path) -> None:
    _, s = made(tmp_path)
    s.factory[341] = -10000  # factory_raw: a number of the type, signed
    signed = ParameterDescription("x", ValueType.I32, Scaling.conversion(-2), "s")
    assert settings_view._factory(s, RAMP, signed) == pytest.approx(-100.0)


async def test_other_software_keeps_the_baseline_and_another_model_starts_anew(
    tmp_path: Path,
) -> None:
    w, s = made(tmp_path)
    s.loaded = True
    await w._identified(s, "fc:FC-102P11KT4|05.11")
    await w._compare(s, RAMP, FMT, 500, 5.0)
    await w._identified(s, "fc:FC-102P11KT4|06.02")  # a software update
    assert s.rows[(341, 0)].baseline_raw == 500
    await w._identified(s, "fc:FC-302P7K5T5|06.02")  # another model
    assert s.rows == {} and [e.code for e in told(w)] == ["baseline"]
