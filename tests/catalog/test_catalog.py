"""Tests for the parameter catalogs and their loader."""

from __future__ import annotations

import textwrap
from dataclasses import replace
from pathlib import Path

import pytest
from pydantic import ValidationError

from pkwbus.catalog import (
    CONVERSION_INDEXES,
    Catalog,
    CatalogError,
    ParameterSpec,
    available_catalogs,
    load_catalog,
    load_catalog_file,
)
from pkwbus.catalog.description import ParameterDescription, name_for_unit
from pkwbus.catalog.loader import _parse_key
from pkwbus.catalog.logs import logs_of_catalog

BUILT_IN = ["danfoss-fc", "siemens-g120", "siemens-mm4"]

HEADER = """\
name: test
dialect: fc
sources:
  m: some manual
parameters:
"""


def write_catalog(tmp_path: Path, body: str, header: str = HEADER) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text(header + textwrap.indent(textwrap.dedent(body), "  "), "utf-8")
    return path


def load_error(tmp_path: Path, body: str, header: str = HEADER) -> str:
    with pytest.raises(CatalogError) as info:
        load_catalog_file(write_catalog(tmp_path, body, header))
    return str(info.value)


# --- built-in catalogs --------------------------------------------------------


def test_available_catalogs_lists_the_built_in_ones() -> None:
    assert available_catalogs() == BUILT_IN


@pytest.mark.parametrize("name", BUILT_IN)
def test_built_in_catalog_loads(name: str) -> None:
    catalog = load_catalog(name)
    assert catalog.name == name
    assert catalog.parameters
    assert load_catalog(name) is catalog  # cached


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_entry_is_named_and_sourced(name: str) -> None:
    catalog = load_catalog(name)
    for pnu, spec in catalog.parameters.items():
        assert spec.pnu == pnu
        assert spec.name.strip(), pnu
        assert spec.source in catalog.sources, pnu
        assert spec.type is not None, pnu


@pytest.mark.parametrize("name", BUILT_IN)
def test_entries_are_consistent(name: str) -> None:
    for pnu, spec in load_catalog(name).parameters.items():
        assert spec.conversion is None or spec.scale is None, pnu
        assert spec.conversion is None or spec.conversion in CONVERSION_INDEXES, pnu
        if spec.min is not None and spec.max is not None:
            assert spec.min <= spec.max, pnu
        if not spec.verified:
            assert spec.note.strip(), pnu


def test_catalog_dialects() -> None:
    assert load_catalog("danfoss-fc").dialect == "fc"
    assert load_catalog("siemens-g120").dialect == "uss"
    assert load_catalog("siemens-mm4").dialect == "uss"


def test_the_micromaster_4_catalog_and_its_fault_buffer() -> None:
    """Only what the MICROMASTER 440 Parameter List's reachable pages (r0948; r2114, P2115)
    and the SED2 Operating Instructions (r0947) give; P2115, a clock, is no setting."""
    mm4 = load_catalog("siemens-mm4")
    assert sorted(mm4.parameters) == [947, 948, 2114, 2115]
    assert [(s.type, s.array, s.verified) for s in mm4.parameters.values()] == [
        ("u16", 8, False), ("u16", 12, True), ("u16", 2, True), ("u16", 3, True),
    ]  # fmt: skip
    assert not any(s.is_setting or s.writable or s.counter for s in mm4.parameters.values())
    assert [log.name for log in logs_of_catalog("siemens-mm4")] == ["MICROMASTER 4 fault buffer"]
    clock = mm4.get(2115)
    assert clock is not None
    assert (clock.min, clock.max, clock.unit) == (0, 65535, "")  # p. 209: Min 0, Max 65535, Unit -
    for spec in mm4.parameters.values():  # each names the document it comes from
        assert "6SE6400-5BB00-0BP0" in mm4.sources[spec.source] or not spec.verified


def test_danfoss_sourced_scaling() -> None:
    fc = load_catalog("danfoss-fc")
    current = fc.get(1614)
    assert current is not None
    assert (current.conversion, current.unit) == (-2, "A")  # 5.24 A is sent as 524
    low_limit = fc.get(412)
    assert low_limit is not None
    assert (low_limit.conversion, low_limit.unit) == (-1, "Hz")  # 10 Hz is sent as 100
    ramp_up = fc.get(341)
    assert ramp_up is not None
    assert (ramp_up.type, ramp_up.conversion, ramp_up.unit) == ("u32", -2, "s")
    assert ramp_up.writable


def test_danfoss_sourced_text_and_array() -> None:
    fc = load_catalog("danfoss-fc")
    fc_type = fc.get(1540)
    assert fc_type is not None
    assert fc_type.type == "text" and fc_type.verified
    alarm_log = fc.get(1530)
    assert alarm_log is not None
    assert alarm_log.array == 10


def test_danfoss_third_party_facts_stay_unverified() -> None:
    frequency = load_catalog("danfoss-fc").get(1613)
    assert frequency is not None
    assert (frequency.type, frequency.conversion, frequency.unit) == ("u16", -1, "Hz")
    assert not frequency.verified


def test_danfoss_monitoring_values_are_not_writable() -> None:
    fc = load_catalog("danfoss-fc")
    for pnu in (1610, 1613, 1614, 1630, 1690, 1500):
        spec = fc.get(pnu)
        assert spec is not None and not spec.writable, pnu


def test_siemens_facts() -> None:
    g120 = load_catalog("siemens-g120")
    current = g120.get(27)
    assert current is not None
    assert (current.type, current.unit) == ("f32", "A")
    speed = g120.get(21)
    assert speed is not None
    assert "Actual speed" in speed.name  # actual value, not the setpoint (r0020)
    faults = g120.get(947)
    assert faults is not None
    assert (faults.type, faults.array, faults.verified) == ("u16", 64, True)
    alarms = g120.get(2110)
    assert alarms is not None and alarms.type == "u16"
    ramp_up = g120.get(1120)
    assert ramp_up is not None
    assert (ramp_up.unit, ramp_up.writable) == ("s", True)
    rated_voltage = g120.get(304)
    assert rated_voltage is not None and not rated_voltage.writable


def test_get_returns_none_for_an_unknown_pnu() -> None:
    assert load_catalog("danfoss-fc").get(9999) is None


def test_unknown_catalog_name_lists_the_available_ones() -> None:
    with pytest.raises(CatalogError) as info:
        load_catalog("abb-acs")
    assert "abb-acs" in str(info.value)
    for name in BUILT_IN:
        assert name in str(info.value)


def test_catalog_name_cannot_walk_out_of_the_data_folder() -> None:
    with pytest.raises(CatalogError):
        load_catalog("../loader")


# --- models -------------------------------------------------------------------


def test_models_are_frozen() -> None:
    catalog = load_catalog("danfoss-fc")
    spec = catalog.get(1613)
    assert spec is not None
    field = "unit"
    with pytest.raises(ValidationError):
        setattr(spec, field, "kHz")
    field = "name"
    with pytest.raises(ValidationError):
        setattr(catalog, field, "other")


def test_spec_defaults() -> None:
    spec = ParameterSpec(pnu=1, name="x")
    assert (spec.unit, spec.writable, spec.verified, spec.note, spec.source) == (
        "",
        False,
        True,
        "",
        "",
    )


def test_catalog_checks_source_keys_when_built_directly() -> None:
    spec = ParameterSpec(pnu=1, name="x", source="nowhere")
    with pytest.raises(ValidationError, match="nowhere"):
        Catalog(name="c", dialect="uss", parameters={1: spec})


def test_override_replaces_fields_and_keeps_the_rest() -> None:
    spec = ParameterSpec(pnu=1500, name="Operating hours", type="u32", conversion=74, unit="s")
    hours = spec.overridden({"scale": 1, "unit": "h"})
    assert (hours.scale, hours.conversion, hours.unit) == (1.0, None, "h")
    assert (hours.pnu, hours.name, hours.type) == (1500, "Operating hours", "u32")
    back = hours.overridden({"conversion": -1})
    assert (back.scale, back.conversion) == (None, -1)
    assert spec.overridden({"type": "text"}).conversion is None


@pytest.mark.parametrize(
    "changes",
    [{"pnu": 2}, {"colour": "red"}, {"conversion": 9}, {"min": 5, "max": 1}, {"type": "u8"}],
)
def test_override_is_validated(changes: dict[str, object]) -> None:
    spec = ParameterSpec(pnu=1, name="x", type="u16", conversion=0)
    with pytest.raises(ValueError):
        spec.overridden(changes)


# --- keys ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "pnu"),
    [
        ("16-13", 1613),
        ("3-41", 341),
        ("4-14", 414),
        ("0-01", 1),
        ("1613", 1613),
        ("r0021", 21),
        ("R0021", 21),
        ("p1082", 1082),
        ("P7841", 7841),
        (" 16-13 ", 1613),
    ],
)
def test_parse_key(text: str, pnu: int) -> None:
    assert _parse_key(text) == pnu


@pytest.mark.parametrize("text", ["16-1", "16-130", "x0021", "16_13", "", "r", "99999", "16-13[2]"])
def test_parse_key_rejects(text: str) -> None:
    with pytest.raises(ValueError, match=r"16-13|index|above|parameter"):
        _parse_key(text)


# --- bad files ----------------------------------------------------------------


def test_unknown_entry_field_names_the_entry(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {name: Frequency, colour: red}\n')
    assert 'bad.yaml: parameters."16-13".colour' in message
    assert "pydantic" not in message


def test_catalog_problems_are_worded_like_the_configs(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {name: Frequency, array: many}\n')
    assert "parameters.\"16-13\".array: must be a whole number, not 'many'" in message
    assert "Input should be" not in message


def test_unknown_top_level_field(tmp_path: Path) -> None:
    message = load_error(
        tmp_path, "", header=HEADER.replace("dialect: fc", "dialect: fc\nvendor: x")
    )
    assert "bad.yaml: vendor: " in message


def test_bad_type(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {name: Frequency, type: u8}\n')
    assert 'parameters."16-13".type:' in message


@pytest.mark.parametrize("conversion", [7, -8, 50, 101])
def test_bad_conversion(tmp_path: Path, conversion: int) -> None:
    message = load_error(tmp_path, f'"16-13": {{name: Frequency, conversion: {conversion}}}\n')
    assert 'parameters."16-13"' in message
    assert f"conversion index {conversion}" in message


def test_conversion_and_scale_exclusive(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {name: Frequency, conversion: -1, scale: 0.1}\n')
    assert 'parameters."16-13": give either conversion or scale' in message


def test_min_above_max(tmp_path: Path) -> None:
    message = load_error(tmp_path, "r0021: {name: speed, min: 10, max: 1}\n")
    assert 'parameters."r0021": min 10.0 is greater than max 1.0' in message


def test_unverified_needs_a_note(tmp_path: Path) -> None:
    message = load_error(tmp_path, "r0021: {name: speed, verified: false}\n")
    assert 'parameters."r0021": verified: false needs a note' in message


def test_text_has_no_scaling(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"15-40": {name: FC Type, type: text, conversion: 0}\n')
    assert 'parameters."15-40"' in message


def test_duplicate_pnu_in_two_notations(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {name: Frequency}\n"1613": {name: Frequency}\n')
    assert 'parameters."1613": PNU 1613 is already defined as "16-13"' in message


def test_duplicate_pnu_with_unquoted_number(tmp_path: Path) -> None:
    message = load_error(tmp_path, "r0021: {name: a}\n21: {name: b}\n")
    assert 'parameters."21": PNU 21 is already defined as "r0021"' in message


def test_same_key_written_twice(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {name: a}\n"16-13": {name: b}\n')
    assert "bad.yaml: line 7, column 3: found duplicate key '16-13' (first at line 6)" in message


def test_bad_key(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-1": {name: Frequency}\n')
    assert 'bad.yaml: parameters."16-1": ' in message


def test_pnu_field_is_not_allowed(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {name: Frequency, pnu: 1613}\n')
    assert 'parameters."16-13".pnu' in message


def test_unknown_source_key(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {name: Frequency, source: nope}\n')
    assert "parameters.\"16-13\".source: 'nope' is not in the sources table" in message


def test_missing_name(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": {type: u16}\n')
    assert 'parameters."16-13".name:' in message


def test_bad_dialect(tmp_path: Path) -> None:
    message = load_error(tmp_path, "", header=HEADER.replace("dialect: fc", "dialect: modbus"))
    assert "bad.yaml: dialect: " in message


def test_entry_must_be_a_mapping(tmp_path: Path) -> None:
    message = load_error(tmp_path, '"16-13": Frequency\n')
    assert 'parameters."16-13": expected a mapping' in message


def test_not_yaml(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("name: [unclosed\n", "utf-8")
    with pytest.raises(CatalogError, match=r"broken\.yaml: line 2, column 1: expected"):
        load_catalog_file(path)


def test_not_a_mapping(tmp_path: Path) -> None:
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n", "utf-8")
    with pytest.raises(CatalogError, match=r"list\.yaml: the file must be a mapping"):
        load_catalog_file(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CatalogError, match="cannot read"):
        load_catalog_file(tmp_path / "absent.yaml")


def test_good_file_loads(tmp_path: Path) -> None:
    path = write_catalog(
        tmp_path,
        """\
        "3-41": {name: Ramp 1 Ramp Up Time, type: u32, conversion: -2, unit: s, source: m}
        1613: {name: Frequency, type: u16, scale: 0.1, unit: Hz}
        p1082: {name: Maximum speed, type: f32, unit: rpm, min: 0, max: 210000}
        """,
    )
    catalog = load_catalog_file(path)
    assert sorted(catalog.parameters) == [341, 1082, 1613]
    spec = catalog.get(1613)
    assert spec is not None and spec.scale == 0.1


# --- enumerations ---------------------------------------------------------------


def test_danfoss_language_options_as_the_design_guide_words_them() -> None:
    # Danfoss VLT HVAC Drive Design Guide MG11BC02, 8.4.10 "Parameter Value (PWE)":
    # "0-01 Language where [0] is English, and [4] is Danish".
    fc = load_catalog("danfoss-fc")
    language = fc.get(1)
    assert language is not None and language.name == "Language"
    assert language.options == {0: "English", 4: "Danish"}
    assert "8.4.10" in fc.sources[language.options_source]
    assert not language.writable


def test_options_load_with_their_source(tmp_path: Path) -> None:
    path = write_catalog(
        tmp_path, '"0-01": {name: Language, type: u16, options: {0: English}, options_source: m}\n'
    )
    spec = load_catalog_file(path).get(1)
    assert spec is not None and spec.options == {0: "English"}


@pytest.mark.parametrize(
    ("entry", "problem"),
    [
        ("type: u16, options: {0: English}", "options need an options_source"),
        ("type: f32, options: {0: English}, options_source: m", "whole-number type"),
        ("options: {0: English}, options_source: m", "whole-number type"),
        ("type: u16, conversion: -1, options: {0: a}, options_source: m", "no conversion"),
        ("type: u16, scale: 0.5, options: {0: a}, options_source: m", "no conversion"),
        ('type: u16, options: {0: " "}, options_source: m', "option 0 has no text"),
        ("type: u16, options: {x: a}, options_source: m", "options.x"),
        ('type: u16, options: {"0": a}, options_source: m', "options.0"),  # a string
        ("type: u16, options: {yes: a}, options_source: m", "whole number, not True"),
        ("type: u16, options: {-1: a}, options_source: m", "option -1 is outside u16"),
        ("type: i16, options: {40000: a}, options_source: m", "option 40000 is outside i16"),
        ("type: u16, options_source: m", "options_source without options"),
    ],
)
def test_options_are_checked(tmp_path: Path, entry: str, problem: str) -> None:
    message = load_error(tmp_path, f'"0-01": {{name: Language, {entry}}}\n')
    assert 'parameters."0-01"' in message and problem in message


def test_options_source_must_be_in_the_sources_table(tmp_path: Path) -> None:
    message = load_error(
        tmp_path, '"0-01": {name: L, type: u16, options: {0: a}, options_source: nope}\n'
    )
    assert "parameters.\"0-01\".options_source: 'nope' is not in the sources table" in message


@pytest.mark.parametrize(
    "changes", [{"type": "f32"}, {"type": "text"}, {"scale": 0.1}, {"conversion": 1}]
)
def test_an_override_that_reads_the_value_another_way_drops_the_options(
    changes: dict[str, object],
) -> None:
    language = load_catalog("danfoss-fc").get(1)
    assert language is not None and language.options
    changed = language.overridden(changes)
    assert (changed.options, changed.options_source) == ({}, "")
    assert language.overridden({"name": "Sprache"}).options == language.options  # kept


@pytest.mark.parametrize("name", BUILT_IN)
def test_a_unit_in_a_name_agrees_with_the_unit_shown(name: str) -> None:
    """16-10 is "Power [kW]" in the vendor's list, but its conversion index scales it to W:
    the name is shown without the unit it would contradict."""
    for pnu, spec in load_catalog(name).parameters.items():
        shown = ParameterDescription.from_spec(spec)
        if "[" in shown.name:
            unit = shown.name.rsplit("[", 1)[1].rstrip("]")
            assert unit.casefold() == shown.unit.casefold(), (pnu, shown.name, shown.unit)


def test_names_without_the_unit_they_would_contradict() -> None:
    power = ParameterDescription.from_spec(load_catalog("danfoss-fc").get(1610))
    assert (power.name, power.unit) == ("Power", "W")
    torque = ParameterDescription.from_spec(load_catalog("danfoss-fc").get(1616))
    assert (torque.name, torque.unit) == ("Torque [Nm]", "Nm")
    assert ParameterDescription("Power [kW]", unit="kW").name == "Power [kW]"
    assert replace(power, unit="kW").name == "Power"  # what was cut stays cut
    assert name_for_unit("Speed [RPM]", "1/s") == "Speed"
    assert name_for_unit("Speed [RPM]", "rpm") == "Speed [RPM]"
    assert name_for_unit("Limit [x] of y", "W") == "Limit [x] of y"  # not at the end


# --- element units ------------------------------------------------------------


def test_the_system_runtime_counts_its_elements_in_their_own_units() -> None:
    # SINAMICS CU240D-2 OI 04/2018, 8.2: "System runtime = r2114[1] x days + r2114[0] x
    # milliseconds": the value has no one unit, each element its own.
    runtime = load_catalog("siemens-g120").get(2114)
    assert runtime is not None and runtime.source == "S-CU240D2-OI"
    assert (runtime.unit, runtime.element_units, runtime.array) == ("", {0: "ms", 1: "d"}, 2)
    described = ParameterDescription.from_spec(runtime)
    assert described.counter and described.element_unit == ""  # the parameter as a whole
    assert [described.at(i).element_unit for i in (0, 1, 2, None)] == ["ms", "d", "", ""]
    assert described.at(0).unit == ""  # the API's and /metrics' unit stays the entry's
    assert ParameterDescription().at(0) == ParameterDescription()


def test_element_units_load(tmp_path: Path) -> None:
    path = write_catalog(tmp_path, "r2114: {name: Runtime, array: 2, element_units: {0: ms}}\n",
                         HEADER.replace("fc", "uss"))  # fmt: skip
    spec = load_catalog_file(path).get(2114)
    assert spec is not None and spec.element_units == {0: "ms"}


@pytest.mark.parametrize(
    ("entry", "problem"),
    [
        ("element_units: {0: ms}", "element_units need an array"),
        ("array: 2, unit: s, element_units: {0: ms}", "either unit (all elements)"),
        ("array: 2, element_units: {2: ms}", "element 2 is outside the array (0 to 1)"),
        ("array: 2, element_units: {-1: ms}", "element -1 is outside the array"),
        ('array: 2, element_units: {0: " "}', "element 0 has no unit"),
        ("array: 2, element_units: {x: ms}", "element_units.x"),
    ],
)
def test_element_units_are_checked(tmp_path: Path, entry: str, problem: str) -> None:
    message = load_error(tmp_path, f'"15-00": {{name: Hours, {entry}}}\n')
    assert 'parameters."15-00"' in message and problem in message


@pytest.mark.parametrize("changes", [{"type": "i32"}, {"scale": 0.1}, {"conversion": -3}])
def test_an_override_that_reads_the_value_another_way_drops_the_element_units(
    changes: dict[str, object],
) -> None:
    runtime = load_catalog("siemens-g120").get(2114)
    assert runtime is not None and runtime.element_units
    assert runtime.overridden(changes).element_units == {}
    assert runtime.overridden({"name": "Laufzeit"}).element_units == runtime.element_units
