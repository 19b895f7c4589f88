"""Values as people read them: to the resolution the scaling gives, floats to about four
significant digits; the API's value keeps full precision."""

from __future__ import annotations

from pathlib import Path

import pytest

from pkwbus.catalog.description import ParameterDescription
from pkwbus.protocol.params import Scaling, ValueType
from pkwbus.service.http.readable import readable
from tests.api.conftest import USS_DRIVES, service


def scaled(index: int, vtype: ValueType = ValueType.U32) -> ParameterDescription:
    return ParameterDescription(vtype=vtype, scaling=Scaling.conversion(index))


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
