"""The drive model's random events, and parameters taken from a catalog."""

from __future__ import annotations

import random
import sys
import types
from dataclasses import dataclass

import pytest

from pkwbus.protocol.pzd import Profile
from pkwbus.sim import ModelConfig, Simulator
from pkwbus.sim.catalogs import CatalogError
from pkwbus.sim.model import DriveModel, Limits
from tests.sim.conftest import FakeClock


def test_warnings_and_trips_come_now_and_then_and_clear() -> None:
    config = ModelConfig(warning_rate=1 / 60, warning_seconds=10, trip_rate=1 / 600)
    model = DriveModel(Profile.FC, random.Random(4), config)
    limits = Limits()
    warnings = trips = 0
    for second in range(1, 36_001):
        was_warning, was_tripped = bool(model.warning_word), model.tripped
        model.update(float(second), limits)
        warnings += bool(model.warning_word) and not was_warning
        trips += model.tripped and not was_tripped
    # ten hours: about 60 trips and, outside warnings, about 500 warnings
    assert 30 < trips < 100 and 300 < warnings < 700
    assert len(model.alarm_log) == 10 and all(model.alarm_log)


@dataclass
class Entry:
    pnu: int
    type: str
    conversion: int = 0
    unit: str = ""
    min: float | None = None
    max: float | None = None
    writable: bool = False


def test_catalog_adds_parameters_and_keeps_live_readings(monkeypatch: pytest.MonkeyPatch) -> None:
    fake = types.ModuleType("pkwbus.catalog")
    entries = [Entry(1613, "u16", -1), Entry(412, "u16", -1, "Hz", 0.0, 500.0, True)]
    fake.load_catalog = lambda name: entries  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "pkwbus.catalog", fake)
    sim = Simulator("fc", [1], catalog="danfoss-fc", seed=1, clock=FakeClock())
    drive = sim.drives[1]
    assert drive.params.specs[1613].live == "frequency"
    assert drive.params.specs[412].writable and drive.value(412) == 0


def test_missing_catalog_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pkwbus.catalog", None)
    with pytest.raises(CatalogError):
        Simulator("fc", [1], catalog="danfoss-fc")
