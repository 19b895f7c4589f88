"""Values as people read them: to the resolution the scaling gives, floats to about four
significant digits; the API's value keeps full precision."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import replace
from fractions import Fraction
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pytest

from pkwbus.catalog import load_catalog
from pkwbus.catalog.description import ParameterDescription, ParameterTable
from pkwbus.catalog.loader import ParameterSpec
from pkwbus.protocol.pkw import Width
from pkwbus.protocol.values import ParameterRef, Scaling, ValueType, decode_value
from pkwbus.service.http.views.readable import TIME_UNITS, duration, readable
from tests.service.http.conftest import USS_DRIVES, service


def scaled(index: int, vtype: ValueType = ValueType.U32) -> ParameterDescription:
    return ParameterDescription(vtype=vtype, scaling=Scaling.conversion(index))


LANGUAGE = ParameterDescription(
    name="Language", vtype=ValueType.U16, options=MappingProxyType({0: "English", 4: "Danish"})
)


@pytest.mark.parametrize(
    ("value", "fmt", "shown"),
    [
        (15.705096244812012, ParameterDescription(vtype=ValueType.F32), "15.71"),
        (5.690357685089111, ParameterDescription(vtype=ValueType.F32), "5.690"),
        (1480.3127, ParameterDescription(vtype=ValueType.F32), "1480"),
        (0.0012346, ParameterDescription(vtype=ValueType.F32), "0.001235"),
        (0.0, ParameterDescription(vtype=ValueType.F32), "0"),
        (43.21, scaled(-2), "43.21"),  # conversion index -2: two decimals
        (50.0, scaled(-1, ValueType.U16), "50.0"),
        (500, scaled(0), "500"),
        (7, ParameterDescription(), "7"),  # a raw number
        (1.0 / 60 * 7, scaled(67), "0.1167"),  # 1/60: no power of ten
        ("PUMP-7", ParameterDescription(vtype=ValueType.TEXT), "PUMP-7"),
        (0, LANGUAGE, "English [0]"),  # an enumeration: its text with the number
        (4, LANGUAGE, "Danish [4]"),
        (2, LANGUAGE, "2"),  # an option no source words: its number alone
        # A drive that describes the value scaled reads it its own way: no option.
        (4.0, replace(LANGUAGE, scaling=Scaling.conversion(-1)), "4.0"),
        (40, replace(LANGUAGE, scaling=Scaling.conversion(1)), "40.00"),
    ],
)
def test_a_value_to_its_resolution(
    value: float | str, fmt: ParameterDescription, shown: str
) -> None:
    assert readable(value, fmt) == shown


async def test_the_drives_view_carries_names_and_readable_values(tmp_path: Path) -> None:
    async with service(tmp_path, uss=USS_DRIVES) as svc:
        drives = {d["name"]: d for d in (await svc.client.get("/api/v1/drives")).json()}
    (speed,) = [v for v in drives["pump1"]["values"] if v["parameter"] == "r0021"]
    assert speed["name"] == "CO: Actual speed smoothed"  # the catalog's
    assert speed["shown"] == readable(speed["value"], ParameterDescription(vtype=ValueType.F32))
    assert len(speed["shown"].replace("-", "").replace(".", "").lstrip("0")) <= 4
    (frequency,) = [v for v in drives["fan1"]["values"] if v["parameter"] == "16-13"]
    assert frequency["name"] == "Frequency"
    assert frequency["shown"] == f"{frequency['value']:.1f}"  # conversion index -1


def table_of(catalog: str) -> ParameterTable:
    """The catalog's entries as the service looks a poll up (its index with it)."""
    specs = load_catalog(catalog).parameters
    return ParameterTable(catalog={p: ParameterDescription.from_spec(s) for p, s in specs.items()})


def time_counters(catalog: str) -> dict[int, ParameterSpec]:
    """The counters the catalog gives a unit of time, as a whole or element by element."""
    return {
        pnu: spec
        for pnu, spec in load_catalog(catalog).parameters.items()
        if spec.counter and {spec.unit, *spec.element_units.values()} & TIME_UNITS.keys()
    }


def test_the_danfoss_hour_counters_read_in_hours() -> None:
    """15-00 Operating hours and 15-01 Running Hours count hours that conversion index 74
    turns into seconds (the catalog's unit): 13 hours are the value 46800 s, read "13 h"."""
    counters = time_counters("danfoss-fc")
    assert sorted(counters) == [1500, 1501]  # 15-02 kWh Counter counts energy, not time
    table = table_of("danfoss-fc")
    for pnu, spec in counters.items():
        fmt = table.describe(ParameterRef(pnu, None, str(pnu)))
        assert (fmt.unit, fmt.scaling) == (spec.unit, Scaling.conversion(74))
        for hours, shown in ((13, "13 h"), (0, "0 h"), (1234, "1,234 h"), (61_000, "61,000 h")):
            value = decode_value(hours, Width.DWORD, fmt.vtype, fmt.scaling)
            assert value == hours * 3600  # the value (and /metrics) stays in seconds
            assert readable(value, fmt) == shown
    # A site that reads them in hours (docs/catalogs.md: scale 1, unit h) reads the same.
    spec = counters[1500].overridden({"scale": 1, "unit": "h"})
    assert readable(13, ParameterDescription.from_spec(spec)) == "13 h"


def test_the_sinamics_system_runtime_reads_as_a_clock_and_in_days() -> None:
    """r2114 System runtime: [0] ms within the day, [1] days (CU240D-2 OI 04/2018, 8.2),
    each element read in its own unit; the value, and its unit (none), as they are."""
    assert sorted(time_counters("siemens-g120")) == [2114]
    table = table_of("siemens-g120")
    units = load_catalog("siemens-g120").parameters[2114].element_units

    def fmt(index: int | None) -> ParameterDescription:
        return table.describe(ParameterRef(2114, index, "r2114"))

    assert (fmt(0).element_unit, fmt(1).element_unit) == (units[0], units[1]) == ("ms", "d")
    assert fmt(0).unit == fmt(1).unit == ""
    assert readable(12_345_678, fmt(0)) == "3:25:45"  # 3 h 25 min 45.678 s
    assert readable(86_399_999, fmt(0)) == "23:59:59"  # the last millisecond of a day
    assert readable(0, fmt(0)) == "0:00:00"
    assert readable(12, fmt(1)) == "12 d"
    assert readable(1234, fmt(1)) == "1,234 d"
    assert readable(12, fmt(None)) == "12"  # the parameter as a whole has no unit


def test_only_counters_of_time_read_as_durations() -> None:
    """A ramp time in s is no counter: to its resolution, as before; 15-02 kWh Counter
    (energy, J) and 15-03 Power Up's neither."""
    fc, siemens = table_of("danfoss-fc"), table_of("siemens-g120")
    ramp = fc.describe(ParameterRef(341, None, "3-41"))
    assert ramp.unit == "s" and readable(10.0, ramp) == "10.00"
    assert readable(3600.0, ramp) == "3600.00"
    ramp_up = siemens.describe(ParameterRef(1120, None, "p1120"))
    assert ramp_up.unit == "s" and readable(7200.0, ramp_up) == "7200"
    energy = fc.describe(ParameterRef(1502, None, "15-02"))
    assert energy.counter and readable(18_000_000, energy) == "18000000"
    power_ups = fc.describe(ParameterRef(1503, None, "15-03"))
    assert power_ups.counter and readable(3600, power_ups) == "3600"


@pytest.mark.parametrize(
    ("value", "unit", "step", "shown"),
    [
        (46800, "s", Fraction(3600), "13 h"),  # counts hours: whole hours
        (13, "h", Fraction(1), "13 h"),
        (12.5, "h", Fraction(1), "12.5 h"),  # a float of hours: to a tenth
        (2, "d", Fraction(1), "2 d"),
        (42, "s", Fraction(1), "0:00:42"),  # finer than an hour: a clock within a day
        (5400, "s", Fraction(1), "1:30:00"),
        (90, "min", Fraction(1), "1:30:00"),
        (1500, "ms", Fraction(1), "0:00:01"),  # the second begun is not counted yet
        (90000, "s", Fraction(1), "25.0 h"),  # above a day: hours to a tenth
        (-1, "s", Fraction(1), None),  # no duration: shown as any other number
        (math.nan, "s", Fraction(1), None),
    ],
)
def test_a_duration_in_its_own_units(
    value: float, unit: str, step: Fraction, shown: str | None
) -> None:
    assert duration(value, unit, step) == shown


def test_a_negative_counter_falls_back_to_its_number() -> None:
    fmt = ParameterDescription(vtype=ValueType.I32, unit="s", counter=True)
    assert readable(-5, fmt) == "-5"


def test_options_apply_only_to_an_unscaled_whole_number() -> None:
    assert LANGUAGE.enumerates and LANGUAGE.option(4) == "Danish"
    scaled_language = replace(LANGUAGE, scaling=Scaling.conversion(-1))
    assert not scaled_language.enumerates and scaled_language.option(4) == ""
    as_float = replace(LANGUAGE, vtype=ValueType.F32)
    assert not as_float.enumerates and as_float.option(4) == ""


async def test_a_name_never_contradicts_the_unit_beside_it(tmp_path: Path) -> None:
    """16-10 "Power [kW]" (the vendor's name) is read in W (its conversion index): the
    view names it without the unit it would contradict."""
    drives = [{"name": "fan1", "address": 1, "catalog": "danfoss-fc",
               "poll": [("16-10", "50ms"), ("16-16", "50ms")]}]  # fmt: skip
    async with service(tmp_path, fc=drives) as svc:
        power = await _until(svc, "16-10", lambda v: v["value"] is not None)
        torque = await _until(svc, "16-16", lambda v: v["value"] is not None)
    assert (power["name"], power["unit"]) == ("Power", "W")
    assert (torque["name"], torque["unit"]) == ("Torque [Nm]", "Nm")


async def test_an_enumeration_in_words_and_a_write_form_with_its_options(tmp_path: Path) -> None:
    drives = [{"name": "fan1", "address": 1, "catalog": "danfoss-fc",
               "poll": [("0-01", "50ms")], "writable": ["0-01"]}]  # fmt: skip
    async with service(tmp_path, fc=drives) as svc:
        (language,) = await _values(svc, "0-01")
        assert (language["value"], language["option"], language["shown"]) == (
            0, "English", "English [0]"
        )  # fmt: skip
        svc.sims["fc"].drives[1].set_value(1, 4)
        language = await _until(svc, "0-01", lambda v: v["value"] == 4)
        assert (language["option"], language["shown"]) == ("Danish", "Danish [4]")
        svc.sims["fc"].drives[1].set_value(1, 2)  # no source words option 2
        language = await _until(svc, "0-01", lambda v: v["value"] == 2)
        assert (language["option"], language["shown"]) == ("", "2")
        drive = await _fan1(svc)
    (form,) = drive["writable"]
    assert form["options"] == {"0": "English", "4": "Danish"}  # JSON keys are strings


async def _fan1(svc: Any) -> dict[str, Any]:
    (drive,) = [d for d in (await svc.client.get("/api/v1/drives")).json() if d["name"] == "fan1"]
    return drive  # type: ignore[no-any-return]


async def _values(svc: Any, parameter: str) -> list[dict[str, Any]]:
    drive = await _fan1(svc)
    return [v for v in drive["values"] if v["parameter"] == parameter]


async def _until(svc: Any, parameter: str, done: Callable[[dict[str, Any]], bool]) -> Any:
    for _ in range(2000):
        found = [v for v in await _values(svc, parameter) if done(v)]
        if found:
            return found[0]
        await asyncio.sleep(0.01)
    raise AssertionError(f"{parameter} never changed: {await _values(svc, parameter)}")
