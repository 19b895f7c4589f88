"""Values as people read them: to the resolution the scaling gives, floats to about four
significant digits; the API's value keeps full precision."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pytest

from pkwbus.catalog.description import ParameterDescription
from pkwbus.protocol.values import Scaling, ValueType
from pkwbus.service.http.readable import readable
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
