"""Configuration, then the drive, then the catalog, field by field; limits scaled as the
values are; a unit never paired with another scaling than its own."""

from __future__ import annotations

from fractions import Fraction
from types import MappingProxyType

from pkwbus.catalog.description import ParameterDescription
from pkwbus.catalog.precedence import Layers, disagreements, resolve
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.values.types import Scaling, ValueType

CATALOG = ParameterDescription(
    "Motor current", ValueType.I32, Scaling.conversion(-2), "A", 0.0, 100.0
)
PLAIN = Layers(CATALOG, catalog=CATALOG)


def test_the_drive_comes_before_the_catalog() -> None:
    drive = DriveDescription(type_code=4, conversion=-3, unit="A", name="MOTOR CURRENT",
                             low_raw=0, high_raw=50_000)  # fmt: skip
    found = resolve(PLAIN, drive)
    assert found.source == "drive"
    assert found.description.scaling.factor == Fraction(1, 1000)
    assert (found.description.minimum, found.description.maximum) == (0.0, 50.0)
    assert found.description.name == "Motor current"  # the catalog's begins with the drive's


def test_the_configuration_comes_before_the_drive_and_scales_its_limits() -> None:
    config = ParameterDescription(scaling=Scaling.scale(0.1), name="Strom")
    layers = Layers(CATALOG, config, frozenset({"scaling", "name"}), CATALOG)
    drive = DriveDescription(type_code=4, conversion=-2, high_raw=5000)
    found = resolve(layers, drive)
    assert found.source == "config"
    assert found.description.scaling.factor == Fraction(1, 10)
    assert found.description.maximum == 500.0  # the raw limit, scaled as the values are
    assert found.description.name == "Strom"


def test_a_drive_without_scaling_has_its_limits_scaled_by_the_catalog() -> None:
    drive = DriveDescription(type_code=4, low_raw=0, high_raw=500)  # no element 4
    found = resolve(PLAIN, drive)
    assert found.description.scaling == CATALOG.scaling
    assert found.description.maximum == 5.0
    assert found.description.unit == "A"


def test_a_unit_stays_with_its_own_scaling() -> None:
    kw = ParameterDescription("Power", ValueType.I32, Scaling.conversion(1), "W")
    other = DriveDescription(type_code=4, conversion=-2, unit="")  # in hundredths of a kW
    assert resolve(Layers(kw, catalog=kw), other).description.unit == ""
    same = DriveDescription(type_code=4, conversion=1, unit=None)
    assert resolve(Layers(kw, catalog=kw), same).description.unit == "W"


def test_nothing_from_the_drive_leaves_the_catalog() -> None:
    assert resolve(PLAIN, None) == resolve(PLAIN, DriveDescription())
    assert resolve(PLAIN, None).description == CATALOG
    assert resolve(PLAIN, None).source == "catalog"
    assert resolve(Layers(ParameterDescription()), None).source == "none"


def test_disagreements_name_field_and_both_values() -> None:
    drive = DriveDescription(type_code=3, conversion=-3, unit="V", low_raw=0, high_raw=200_000)
    found = {d.field: (d.drive, d.catalog) for d in disagreements(drive, CATALOG)}
    assert found == {
        "type": ("i16", "i32"),
        "scaling": ("x0.001", "x0.01"),
        "unit": ("V", "A"),
        "max": ("200", "100"),
    }
    assert disagreements(DriveDescription(type_code=4, conversion=-2, unit="A"), CATALOG) == []


def test_the_catalogs_options_stand_only_while_the_drive_reads_the_number_unscaled() -> None:
    language = ParameterDescription(
        "Language", ValueType.U16, options=MappingProxyType({0: "English", 4: "Danish"})
    )
    layers = Layers(language, catalog=language)
    plain = resolve(layers, DriveDescription(type_code=6, conversion=0)).description  # U16
    assert plain.enumerates and plain.option(4) == "Danish"
    scaled = resolve(layers, DriveDescription(type_code=6, conversion=-1)).description
    assert not scaled.enumerates and scaled.option(4) == ""  # raw 40 is no "Danish"


def test_an_element_unit_stays_with_its_own_scaling() -> None:
    """r2114's elements count ms and days unscaled: a drive that describes another
    scaling reads them another way, so the catalog's element units no longer apply."""
    runtime = ParameterDescription(
        "System runtime", ValueType.U32, array=2, counter=True,
        element_units=MappingProxyType({0: "ms", 1: "d"}),
    ).at(0)  # fmt: skip
    layers = Layers(runtime, catalog=runtime)
    same = resolve(layers, DriveDescription(type_code=7, array=2)).description
    assert same.element_unit == "ms"
    other = resolve(layers, DriveDescription(type_code=7, conversion=-3)).description
    assert (other.element_unit, dict(other.element_units)) == ("", {})
