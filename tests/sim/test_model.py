"""The drive model's random events, and parameters taken from a catalog."""

from __future__ import annotations

import dataclasses
import random

import pytest

from pkwbus.catalog import load_catalog
from pkwbus.catalog.description import ParameterDescription
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pzd import Profile
from pkwbus.protocol.values import ValueType, decode_value
from pkwbus.sim import ModelConfig, Simulator
from pkwbus.sim.drives.catalogs import UNIT_FACTORS, CatalogError
from pkwbus.sim.drives.model import DriveModel, Limits
from pkwbus.sim.drives.table import FC_TABLE, TABLES
from tests.sim.conftest import FakeClock

QUIET = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0)


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


@pytest.mark.parametrize(
    ("protocol", "catalog", "pnu", "quantity", "factor"),
    [
        ("fc", "danfoss-fc", 1613, "frequency", 1.0),
        ("fc", "danfoss-fc", 1610, "power", 1000.0),  # the model's kW, the catalog's W
        ("uss", "siemens-g120", 27, "current", 1.0),
        ("uss", "siemens-g120", 21, "frequency", 30.0),  # Hz of a 4-pole motor as rpm
    ],
)
def test_catalog_readings_decode_to_the_models_quantity(
    protocol: str, catalog: str, pnu: int, quantity: str, factor: float
) -> None:
    """A master decoding with the catalog reads the model's value in the catalog's unit."""
    sim = Simulator(protocol, [1], catalog=catalog, seed=1, clock=FakeClock())
    drive = sim.drives[1]
    spec = load_catalog(catalog).get(pnu)
    assert spec is not None and spec.type is not None
    fmt = ParameterDescription.from_spec(spec)
    vtype = ValueType(spec.type)
    width = vtype.width
    assert width is not None
    got = decode_value(drive.value(pnu), width, vtype, fmt.scaling)
    expected = drive.params.live(quantity, 0) * factor
    # current and power carry noise from one reading to the next: a few percent
    assert float(got) == pytest.approx(expected, rel=0.03, abs=float(fmt.scaling.factor))


def test_catalog_adds_parameters_the_table_lacks() -> None:
    sim = Simulator("fc", [1], catalog="danfoss-fc", seed=1, clock=FakeClock())
    specs = sim.drives[1].params.specs
    assert 1613 in specs and specs[1613].live == "frequency"
    assert 1634 in specs  # heatsink temperature: only in the catalog


def test_unknown_catalog_is_a_clear_error() -> None:
    with pytest.raises(CatalogError, match="nonesuch"):
        Simulator("fc", [1], catalog="nonesuch")


@pytest.mark.parametrize(
    ("protocol", "catalog", "pnu", "model_unit"),
    [
        ("uss", "siemens-g120", 1082, "Hz"),  # maximum speed: the table's Hz, the catalog's rpm
        ("fc", "danfoss-fc", 120, "kW"),  # motor power: the table's kW, the catalog's W
    ],
)
def test_catalog_settings_start_at_the_tables_value_in_the_catalogs_unit(
    protocol: str, catalog: str, pnu: int, model_unit: str
) -> None:
    table = next(s for s in TABLES[Bus(protocol)] if s.pnu == pnu)
    assert table.unit == model_unit and isinstance(table.initial, float)
    spec = load_catalog(catalog).get(pnu)
    assert spec is not None and spec.type is not None and spec.unit != model_unit
    sim = Simulator(protocol, [1], catalog=catalog, seed=1, clock=FakeClock())
    fmt = ParameterDescription.from_spec(spec)
    vtype = ValueType(spec.type)
    assert vtype.width is not None
    got = decode_value(sim.drives[1].value(pnu), vtype.width, vtype, fmt.scaling)
    assert float(got) == pytest.approx(table.initial * UNIT_FACTORS[model_unit, spec.unit])


def test_the_model_reads_its_limits_in_its_own_units() -> None:
    """A maximum frequency served in rpm still steers the model in Hz."""
    factor = UNIT_FACTORS["Hz", "rpm"]
    specs = tuple(
        dataclasses.replace(s, unit="rpm", unit_factor=factor, initial=50.0 * factor)
        if s.pnu == 414
        else s
        for s in FC_TABLE
    )
    in_hz = Simulator("fc", [1], seed=1, clock=FakeClock(), model=QUIET)
    in_rpm = Simulator("fc", [1], seed=1, clock=FakeClock(), model=QUIET, specs=specs)
    assert in_rpm.drives[1].limits() == in_hz.drives[1].limits()
    assert in_rpm.drives[1].value(1613) == in_hz.drives[1].value(1613)
