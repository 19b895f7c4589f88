"""The configuration file: valid files, every kind of problem with its place, fuzzing."""

from __future__ import annotations

import copy
import functools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pkwbus.catalog import ParameterSpec, available_catalogs
from pkwbus.link import PortSettings
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.dialects import IndLayout
from pkwbus.protocol.serial.telegram import FC_PARAMETER, BlockShape, FcAddressFormat
from pkwbus.protocol.values import ParameterRef, Scaling, ValueType
from pkwbus.service.config import (
    Catalogs,
    Config,
    ConfigError,
    Drive,
    Line,
    Listen,
    SimPort,
    load_config,
    parse_config,
    parse_duration,
    parse_listen,
    parse_sim_port,
)

ROOT = Path(__file__).resolve().parents[3]
DEMO = ROOT / "config" / "demo.yaml"
EXAMPLE = ROOT / "config" / "example.yaml"
BAD = Path(__file__).parent / "bad_configs"


def drive_named(config: Config, name: str) -> tuple[Line, Drive] | None:
    return next(((ln, d) for ln, d in config.drives() if d.name == name), None)


class FakeCatalog:
    """A catalog that knows a few PNUs, standing in for pkwbus.catalog in these tests."""

    def __init__(self, pnus: set[int]) -> None:
        self.pnus = pnus

    def get(self, pnu: int, /) -> ParameterSpec | None:
        if pnu not in self.pnus:
            return None
        return ParameterSpec(pnu=pnu, name=f"parameter {pnu}", type="u16", min=0, max=100)


FAKE_CONTENTS: Mapping[str, set[int]] = {
    "danfoss-fc": {1613, 1614, 1610, 1630, 1690, 1692, 1530, 341, 342},
    "siemens-g120": {21, 24, 27, 947, 1120, 1121},
}


def fake_load(name: str) -> FakeCatalog:
    if name not in FAKE_CONTENTS:
        raise LookupError(f"unknown catalog {name!r}")
    return FakeCatalog(FAKE_CONTENTS[name])


FAKE = Catalogs(load=fake_load, available=lambda: tuple(FAKE_CONTENTS))

MINIMAL = """
lines:
  - name: l1
    port: /dev/ttyUSB0
    protocol: fc
    baudrate: 19200
    drives:
      - {name: fan, address: 1}
"""


def parse(text: str, environ: Mapping[str, str] | None = None) -> Config:
    return parse_config(text, environ=environ or {}, catalogs=FAKE)


def problems_of(text: str, environ: Mapping[str, str] | None = None) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse(text, environ)
    return caught.value.problems


def with_drive(drive: str, protocol: str = "fc", line: str = "") -> str:
    return f"""
lines:
  - name: l1
    port: /dev/ttyUSB0
    protocol: {protocol}
    baudrate: 19200
{line}    drives:
      - {drive}
"""


# ------------------------------------------------------------ valid files


def test_demo_loads_with_its_defaults() -> None:
    config = load_config(DEMO, environ={}, catalogs=FAKE)
    assert [line.name for line in config.lines] == ["fc_line", "uss_line", "dp_line"]
    fc_line, uss_line, dp_line = config.lines
    # 3 refuses AK 4; a setting changed at a keypad about every five minutes
    assert fc_line.sim == SimPort(Bus.FC, (1, 2, 3), 0.003, (3,), keypad_every=300.0)
    assert uss_line.sim == SimPort(Bus.USS, (1, 2), 0.005)
    assert dp_line.sim == SimPort(Bus.PROFIBUS, (8, 9, 10))
    assert [d.pkw_dialect.name for d in dp_line.drives] == [
        "danfoss-pcv", "profidrive", "hitachi-sjpb",
    ]  # fmt: skip
    names = [d.name for _, d in config.drives()]
    assert names == [
        "supply_fan", "exhaust_fan", "pump_3", "conveyor", "mixer", "extruder", "blower", "hoist",
    ]  # fmt: skip
    _, fan = drive_named(config, "supply_fan") or pytest.fail("no supply_fan")
    assert [str(p.ref) for p in fan.poll] == [
        "16-13", "16-14", "16-10", "16-30", "16-90", "16-92", "15-30[0]", "0-01",
    ]  # fmt: skip
    assert [p.every for p in fan.poll] == [1, 1, 2, 2, 5, 5, 30, 60]
    assert fan.may_write(ParameterRef(341, None, "341"))
    assert not fan.may_write(ParameterRef(1613, None, "16-13"))
    _, conveyor = drive_named(config, "conveyor") or pytest.fail("no conveyor")
    assert conveyor.pkw_dialect.name == "uss"
    assert conveyor.shape == BlockShape(4, 2)
    assert conveyor.poll[-1].ref == ParameterRef(947, 0, "r0947")


def test_example_loads() -> None:
    config = load_config(EXAMPLE, environ={}, catalogs=FAKE)
    (line,) = config.lines
    assert line.port.startswith("/dev/serial/by-id/")  # the name check-config recommends
    assert line.sim is None
    (drive,) = line.drives
    assert drive.overrides_for(ParameterRef(341, None, "3-41")).max == 60
    assert drive.overrides_for(ParameterRef(1617, None, "16-17")).unit == "rpm"
    assert drive.overrides_for(ParameterRef(1617, None, "16-17")).scale == 1


def test_demo_loads_with_the_builtin_catalogs() -> None:
    config = load_config(DEMO, environ={})
    for _, drive in config.drives():
        for entry in drive.poll:
            assert drive.spec(entry.ref) is not None, (drive.name, str(entry.ref))


def test_specs_from_the_builtin_catalogs_with_overrides() -> None:
    config = load_config(EXAMPLE, environ={})
    _, fan = drive_named(config, "supply_fan") or pytest.fail("no supply_fan")
    ramp = fan.spec(ParameterRef(341, None, "3-41"))
    assert ramp is not None
    assert (ramp.name, ramp.type, ramp.conversion) == ("Ramp 1 Ramp Up Time", "u32", -2)
    assert ramp.unit == "s"
    assert (ramp.min, ramp.max) == (1, 60)  # the config's limits over the catalog's
    speed = fan.spec(ParameterRef(1617, None, "16-17"))
    assert speed is not None
    assert (speed.scale, speed.conversion, speed.unit) == (1, None, "rpm")
    assert fan.spec(ParameterRef(4095, None, "4095")) is None


def test_spec_from_overrides_alone() -> None:
    text = with_drive(
        "{name: d, address: 1, poll: [{parameter: 1234, every: 1s, type: i16, scale: 0.5}]}"
    )
    drive = parse(text).lines[0].drives[0]
    spec = drive.spec(drive.poll[0].ref)
    assert spec is not None
    assert (spec.pnu, spec.name, spec.type, spec.scale) == (1234, "1234", "i16", 0.5)


def test_index_beyond_the_catalogs_array() -> None:
    text = with_drive(
        "{name: d, address: 1, catalog: danfoss-fc, poll: [{parameter: '15-30[10]', every: 1s}]}"
    )
    with pytest.raises(ConfigError) as caught:
        parse_config(text, environ={})
    assert caught.value.problems == [
        "lines[0].drives[0].poll[0].parameter: 15-30[10]: the catalog gives it 10 elements"
    ]


def test_unknown_catalog_names_the_builtin_ones() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(with_drive("{name: d, address: 1, catalog: abb}"), environ={})
    builtin = ", ".join(sorted(available_catalogs()))
    assert {"danfoss-fc", "siemens-g120", "siemens-mm4"} <= set(available_catalogs())
    assert caught.value.problems == [
        f"lines[0].drives[0].catalog: unknown catalog 'abb' (available: {builtin})"
    ]


def test_defaults_are_filled_in() -> None:
    config = parse(MINIMAL)
    assert config.listen == Listen(host="127.0.0.1", port=9725)
    assert config.api.write_token_env == "PKWBUS_WRITE_TOKEN"
    assert config.audit_db == Path("var/audit.sqlite")
    assert config.log_format == "text"
    (line,) = config.lines
    assert (line.parity, line.stopbits, line.timeout, line.retries) == ("E", 1, 0.1, 2)
    assert (line.pause, line.inter_char_timeout, line.echo) == (None, None, False)
    assert line.address_format is FcAddressFormat.RANGE_1_126
    assert line.bits_per_character == 11
    assert line.pause_seconds == pytest.approx(3.5 * 11 / 19200)
    # What the line's receiver really waits for a gap, not the start pause.
    receiver = TelegramPort(PortSettings("loop://", baudrate=line.baudrate), Bus.FC)
    assert line.inter_char_seconds == receiver.inter_char_timeout
    assert line.inter_char_seconds > line.pause_seconds
    assert line.response_delay_seconds is None
    (drive,) = line.drives
    assert drive.protocol is Bus.FC
    assert drive.pkw_dialect.name == "fc"
    assert drive.layout is IndLayout.USS
    assert drive.shape == FC_PARAMETER
    assert (drive.catalog, drive.poll, drive.writable, drive.parameters) == (None, [], [], {})


@pytest.mark.parametrize(
    ("dialect", "layout"),
    [
        ("uss", IndLayout.USS),
        ("profidrive", IndLayout.PROFIDRIVE),
        ("danfoss-pcv", IndLayout.PROFIDRIVE),
        ("hitachi-sjpb", IndLayout.PROFIDRIVE),
    ],
)
def test_uss_dialects_and_their_ind_layouts(dialect: str, layout: IndLayout) -> None:
    config = parse(with_drive(f"{{name: d, address: 0, dialect: {dialect}}}", "uss"))
    drive = config.lines[0].drives[0]
    assert (drive.protocol, drive.pkw_dialect.name, drive.layout) == (Bus.USS, dialect, layout)
    assert drive.shape == BlockShape(4, 2)


def test_uss_drive_settings() -> None:
    drive_text = "{name: d, address: 30, ind_layout: profidrive, pkw_words: variable, pzd_words: 6}"
    drive = parse(with_drive(drive_text, "uss")).lines[0].drives[0]
    assert drive.layout is IndLayout.PROFIDRIVE
    assert drive.shape == BlockShape(None, 6)
    assert parse(with_drive("{name: d, address: 1, pkw_words: 127}", "uss")).lines[0].drives[
        0
    ].shape == BlockShape(None, 2)


def test_fc_1_31_format_and_line_timing() -> None:
    line_text = (
        "    fc_address_format: 1-31\n    parity: n\n    stopbits: 2\n"
        "    pause: 2ms\n    inter_char_timeout: 1ms\n    response_delay: 20ms\n    echo: true\n"
    )
    line = parse(with_drive("{name: d, address: 31}", line=line_text)).lines[0]
    assert line.address_format is FcAddressFormat.RANGE_1_31
    assert (line.parity, line.bits_per_character, line.echo) == ("N", 11, True)
    assert (line.pause_seconds, line.inter_char_seconds) == (0.002, 0.001)
    assert line.response_delay_seconds == 0.02


def test_poll_overrides_and_parameters() -> None:
    drive_text = """{name: d, address: 1, catalog: danfoss-fc,
        poll: [{parameter: "15-30", index: 2, every: 250ms, type: U16, conversion: -1,
                unit: Hz, min: 0, max: 50.5, name: alarm}],
        writable: ["3-41[1]"],
        parameters: {"3-41": {type: u32, scale: 0.01, unit: s}, 1613: {unit: Hz}}}"""
    drive = parse(with_drive(drive_text)).lines[0].drives[0]
    (entry,) = drive.poll
    assert entry.ref == ParameterRef(1530, 2, "15-30")
    assert entry.every == 0.25
    assert entry.type is ValueType.U16
    assert entry.scaling == Scaling.conversion(-1)
    assert (entry.unit, entry.min, entry.max, entry.name) == ("Hz", 0, 50.5, "alarm")
    assert drive.overrides_for(entry.ref) == entry.overrides()
    ramp = drive.overrides_for(ParameterRef(341, 1, "3-41"))
    assert (ramp.type, ramp.scaling, ramp.unit) == (ValueType.U32, Scaling.scale(0.01), "s")
    assert drive.overrides_for(ParameterRef(1613, None, "16-13")).unit == "Hz"
    assert not drive.overrides_for(ParameterRef(999, None, "999")).given()
    assert drive.may_write(ParameterRef(341, 1, "3-41"))
    assert not drive.may_write(ParameterRef(341, 2, "3-41"))


def test_a_number_in_exponent_form_is_a_number() -> None:
    """YAML 1.1 reads 1e3 (no point) as text; the configuration takes it as the number it
    is, and still refuses text that is no number."""
    drive_text = """{name: d, address: 1, catalog: danfoss-fc,
        parameters: {"3-41": {min: 5E-1, max: 1e3}}}"""
    drive = parse(with_drive(drive_text)).lines[0].drives[0]
    limits = drive.overrides_for(ParameterRef(341, None, "3-41"))
    assert (limits.min, limits.max) == (0.5, 1000.0)
    with pytest.raises(ConfigError) as refused:
        parse(with_drive('{name: d, address: 1, parameters: {"3-41": {max: "1e3x"}}}'))
    assert "is not a number" in str(refused.value)


def test_ipv6_listen_and_its_text() -> None:
    config = parse("listen: '[::1]:9000'\n" + MINIMAL)
    assert (config.listen.host, config.listen.port) == ("::1", 9000)
    assert str(config.listen) == "[::1]:9000"


def test_problem_places_are_relative_to_the_whole_file() -> None:
    text = MINIMAL + "  - name: l2\n    port: x\n    protocol: uss\n    baudrate: 9600\n"
    text += "    drives:\n      - {name: a, address: 1}\n      - {name: b, address: 99}\n"
    assert problems_of(text) == ["lines[1].drives[1].address: 99 is outside 0-30 for protocol uss"]


def test_several_problems_are_all_reported() -> None:
    text = with_drive("{name: 'a b', address: 0, pol: []}", line="    parity: Q\n")
    found = problems_of(text)
    assert len(found) == 3
    assert any(p.startswith("lines[0].parity: ") for p in found)
    assert any(p.startswith("lines[0].drives[0].name: ") for p in found)
    assert any(p.startswith("lines[0].drives[0].pol: ") for p in found)


# ------------------------------------------------------- broken files


EXPECTED: dict[str, str] = {
    "address_range_fc": "lines[0].drives[0].address: 130 is outside 1-126 for protocol fc",
    "address_range_fc_1_31": (
        "lines[0].drives[0].address: 40 is outside 1-31 for protocol fc with fc_address_format 1-31"
    ),
    "address_range_uss": "lines[0].drives[0].address: 31 is outside 0-30 for protocol uss",
    "address_text": "lines[0].drives[0].address: must be a whole number, not '7'",
    "bad_baudrate": "lines[0].baudrate: 19201 is not a supported baud rate",
    "bad_conversion": "lines[0].drives[0].poll[0].conversion: conversion index 9 is not one of",
    "bad_duration": "lines[0].drives[0].poll[0].every: '1 week' is not a duration",
    "bad_listen": "listen: 'localhost' is not HOST:PORT",
    "bad_listen_port": "listen: '127.0.0.1:70000': the TCP port must be 0-65535 (0: any free port)",
    "bad_log_format": "log_format: must be 'text' or 'json', not 'xml'",
    "bad_name": "lines[0].drives[0].name: may contain only letters, digits and _ . -",
    "bad_notation": "lines[0].drives[0].poll[0].parameter: '16-1x' is not a parameter",
    "bad_parity": "lines[0].parity: must be 'E', 'O' or 'N'",
    "bad_pkw_words": "lines[0].drives[0].pkw_words: 5 is not a PKW length",
    "bad_token_env": "api.write_token_env: 'my-token' is not an environment variable name",
    "bad_type": "lines[0].drives[0].poll[0].type: unknown type 'u33'",
    "drives_not_list": "lines[0].drives: must be a list, not a mapping",
    "duplicate_address": "lines[0].drives[1].address: address 1 is already used by fan",
    "duplicate_drive_name": (
        "lines[1].drives[0].name: drive name 'fan' is already used at lines[0].drives[0]"
    ),
    "duplicate_line_name": "lines[1].name: line name 'l1' is already used by lines[0]",
    "duplicate_poll": "lines[0].drives[0].poll[1].parameter: 1613 is polled twice",
    "duplicate_yaml_key": "line 7, column 5: found duplicate key 'port' (first at line 4)",
    "echo_not_bool": "lines[0].echo: must be true or false, not 'maybe'",
    "empty": "the file is empty",
    "fc_format_on_uss": "lines[0].fc_address_format: applies to protocol fc only",
    "index_twice": "lines[0].drives[0].poll[0].index: the index is already in 15-30[0]",
    "min_above_max": "lines[0].drives[0].parameters[3-41].min: 10.0 is above max 5.0",
    "missing_address": "lines[0].drives[0].address: is required",
    "missing_lines": "lines: is required",
    "negative_retries": "lines[0].retries: must be 0 or more, not -1",
    "negative_timeout": "lines[0].timeout: '-100ms' is not a duration above 0",
    "no_lines": "lines: must not be empty",
    "override_conflicts_catalog": (
        "lines[0].drives[0].parameters[3-41]: 3-41: min 200.0 is greater than max 100.0"
    ),
    "writable_read_only": "lines[0].drives[0].writable[1]: r0021 is read-only (r)",
    "pkw_words_on_fc": "lines[0].drives[0].pkw_words: applies to protocol uss only",
    "pkw_zero_with_polls": "lines[0].drives[0].pkw_words: is 0: the drive has no parameter",
    "pnu_too_big_fc": (
        "lines[0].drives[0].poll[0].parameter: 5000: parameter number 5000 cannot be "
        "encoded in the fc dialect (0-4095)"
    ),
    "pnu_too_big_pcv": (
        "lines[0].drives[0].writable[0]: p2100: parameter number 2100 cannot be encoded "
        "in the danfoss-pcv dialect (0-2047)"
    ),
    "scale_and_conversion": "lines[0].drives[0].poll[0].conversion: give scale or conversion",
    "sim_missing_drive": "lines[0].port: simulates no drive at address 1",
    "sim_mixed_shapes": "lines[0].drives[1]: the simulated drives of a sim:// port share one",
    "sim_no_drives": "lines[0].port: 'sim://fc': list the simulated drives",
    "sim_protocol_mismatch": "lines[0].port: simulates protocol uss but the line's is fc",
    "sim_unknown_option": "lines[0].port: 'sim://fc?drives=1&lag=2': unknown option 'lag'",
    "top_level_list": "the top level must be a mapping (key: value), not a list",
    "unhashable_key": "line 11, column 13: found a key that is not a plain value",
    "unknown_catalog": (
        "lines[0].drives[0].catalog: unknown catalog 'danfoss-xx' "
        "(available: danfoss-fc, siemens-g120)"
    ),
    "unknown_dialect": "lines[0].drives[0].dialect: unknown dialect 'abb'",
    "unknown_drive_key": "lines[0].drives[0].pol: is not a known setting; did you mean poll?",
    "protocol_on_drive": (
        "lines[0].drives[0].protocol: is the line's setting: give the protocol once, on the line"
    ),
    "unknown_scheme": "lines[0].port: unknown port URL scheme 'tcp'",
    "unknown_top_key": "lisen: is not a known setting; did you mean listen?",
    "wrong_dialect": "lines[0].drives[0].dialect: uss is not for protocol fc (use fc)",
    "wrong_writable": "lines[0].drives[0].writable: must be a list, not '3-41'",
    "yaml_syntax": "line 12, column 1: expected ',' or '}'",
    "zero_duration": "lines[0].drives[0].poll[0].every: 0 is not a duration above 0",
    "wrong_type_timeout_list": "lines[0].timeout: a list is not a duration",
    "wrong_type_retries_float": "lines[0].retries: must be a whole number, not 2.5",
    "wrong_type_poll_entry": "lines[0].drives[0].poll[0]: must be a mapping (key: value)",
    "wrong_type_drive_name": "lines[0].drives[0].name: must be text, not 12",
    "unknown_line_key": "lines[0].retry: is not a known setting; did you mean retries?",
    "unknown_poll_key": "lines[0].drives[0].poll[0].unitt: is not a known setting; did you mean",
    "duplicate_drive_name_one_line": (
        "lines[0].drives[1].name: drive name 'fan' is already used at lines[0].drives[0]"
    ),
    "address_zero_fc": "lines[0].drives[0].address: 0 is outside 1-126 for protocol fc",
    "address_negative_uss": "lines[0].drives[0].address: -1 is outside 0-30 for protocol uss",
    "bad_notation_writable": "lines[0].drives[0].writable[0]: '3-4x' is not a parameter",
    "bad_notation_parameters_key": "lines[0].drives[0].parameters[q341]: 'q341' is not a parameter",
    "pnu_too_big_uss": "lines[0].drives[0].poll[0].parameter: '70000': parameter number 70000 is",
    "pnu_too_big_fc_writable": (
        "lines[0].drives[0].writable[0]: p9000: parameter number 9000 cannot be encoded "
        "in the fc dialect (0-4095)"
    ),
    "bad_duration_unit": "lines[0].drives[0].poll[0].every: '1d' is not a duration",
    "negative_every": "lines[0].drives[0].poll[0].every: '-1s' is not a duration above 0",
    "bad_duration_pause": "lines[0].pause: 'short' is not a duration",
}


def test_every_broken_file_has_an_expectation() -> None:
    assert sorted(p.stem for p in BAD.glob("*.yaml")) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_broken_file_names_its_place(name: str) -> None:
    with pytest.raises(ConfigError) as caught:
        load_config(BAD / f"{name}.yaml", environ={}, catalogs=FAKE)
    problems = caught.value.problems
    assert any(p.startswith(EXPECTED[name]) for p in problems), problems
    for problem in problems:
        assert "Input should" not in problem and "Value error" not in problem
        assert "\n" not in problem


def test_unreadable_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError) as caught:
        load_config(missing, environ={}, catalogs=FAKE)
    assert caught.value.problems == [f"{missing}: cannot read: No such file or directory"]
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path, environ={}, catalogs=FAKE)


def test_file_that_is_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes(b"lines: [\xff]\n")
    with pytest.raises(ConfigError, match="not UTF-8"):
        load_config(path, environ={}, catalogs=FAKE)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("just text", "the top level must be a mapping (key: value), not text"),
        ("42", "the top level must be a mapping (key: value), not a number"),
        ("a: !!python/object:os.system x", "line 1, column 4: could not determine a constructor"),
        ("lines: *nothing", "line 1, column 8: found undefined alias 'nothing'"),
        (
            "{lines: 1, lines: 2}",
            "line 1, column 12: found duplicate key 'lines' (first at line 1)",
        ),
    ],
)
def test_yaml_level_problems(text: str, expected: str) -> None:
    (problem,) = problems_of(text)
    assert problem.startswith(expected)


def test_merge_keys_fill_a_line() -> None:
    """Keys given next to a merge key override it: not duplicates."""
    text = """
lines:
  - &first
    name: l1
    port: /dev/ttyUSB0
    protocol: fc
    baudrate: 19200
    drives: [{name: a, address: 1}]
  - <<: *first
    name: l2
    port: /dev/ttyUSB1
    drives: [{name: b, address: 1}]
"""
    config = parse(text)
    assert [(ln.name, ln.port, ln.baudrate) for ln in config.lines] == [
        ("l1", "/dev/ttyUSB0", 19200),
        ("l2", "/dev/ttyUSB1", 19200),
    ]


# -------------------------------------------------------------- durations


@pytest.mark.parametrize(
    ("text", "seconds"),
    [
        ("250ms", 0.25),
        ("1s", 1.0),
        ("1.5s", 1.5),
        ("5m", 300.0),
        ("2min", 120.0),
        ("1h", 3600.0),
        (" 10 ms ", 0.01),
        ("0.1", 0.1),
        (".5", 0.5),
        (2, 2.0),
        (0.05, 0.05),
    ],
)
def test_durations(text: str | float, seconds: float) -> None:
    assert parse_duration(text) == pytest.approx(seconds)


@pytest.mark.parametrize(
    "text", ["", "s", "1 week", "1d", "-1s", "0", 0, 0.0, -3, True, None, [1], "nan", float("inf")]
)
def test_bad_durations(text: object) -> None:
    with pytest.raises(ValueError, match="duration"):
        parse_duration(text)


def test_huge_integer_duration() -> None:
    with pytest.raises(ValueError, match="not a finite duration"):
        parse_duration(10**400)


# ---------------------------------------------------------- listen, sim


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("127.0.0.1:9725", ("127.0.0.1", 9725)),
        ("0.0.0.0:80", ("0.0.0.0", 80)),
        ("localhost:1", ("localhost", 1)),
        ("[::1]:9725", ("::1", 9725)),
        ("[::]:65535", ("::", 65535)),
    ],
)
def test_listen(text: str, expected: tuple[str, int]) -> None:
    assert parse_listen(text) == expected


@pytest.mark.parametrize(
    "text",
    ["9725", ":9725", "::1:9725", "[::1]", "[zz]:1", "host:-1", "host:x", "a b:1", "h:99999"],
)
def test_bad_listen(text: str) -> None:
    with pytest.raises(ValueError):
        parse_listen(text)


def test_sim_ports() -> None:
    assert parse_sim_port("sim://fc?drives=1,2,5-7") == SimPort(Bus.FC, (1, 2, 5, 6, 7))
    assert parse_sim_port("sim://USS?drives=0&response_delay=3ms") == SimPort(Bus.USS, (0,), 0.003)
    assert parse_sim_port("sim://fc?drives=1-3&refuse_descriptions=3") == SimPort(
        Bus.FC, (1, 2, 3), None, (3,)
    )


@pytest.mark.parametrize(
    "url",
    [
        "sim://modbus?drives=1",
        "sim://fc",
        "sim://fc?drives=",
        "sim://fc?drives=a",
        "sim://fc?drives=200",
        "sim://fc?drives=1&drives=2",
        "sim://fc?drives=1&response_delay=soon",
        "sim://fc/x?drives=1",
        "sim://fc?drives",
        "sim://fc?drives=1&refuse_descriptions=2",  # not a simulated drive
        "sim://fc?drives=1&refuse_descriptions=x",
    ],
)
def test_bad_sim_ports(url: str) -> None:
    with pytest.raises(ValueError):
        parse_sim_port(url)


# ------------------------------------------------------ environment


def test_listen_from_the_environment() -> None:
    config = parse(MINIMAL, environ={"PKWBUS_LISTEN": "0.0.0.0:8000"})
    assert str(config.listen) == "0.0.0.0:8000"
    (problem,) = problems_of(MINIMAL, environ={"PKWBUS_LISTEN": "nowhere"})
    assert problem.startswith("PKWBUS_LISTEN (overrides listen): 'nowhere' is not HOST:PORT")


def test_with_listen() -> None:
    config = parse(MINIMAL)
    assert str(config.with_listen("[::1]:1234").listen) == "[::1]:1234"
    assert config.with_listen("[::1]:1234").lines == config.lines
    with pytest.raises(ConfigError) as caught:
        config.with_listen("nope")
    assert caught.value.problems[0].startswith("--listen: 'nope' is not HOST:PORT")


SECRET = "s3cret-T0ken-value"


def test_write_token_comes_from_the_named_variable_and_never_shows() -> None:
    text = "api: {write_token_env: MY_TOKEN}\n" + MINIMAL
    config = parse(text, environ={"MY_TOKEN": SECRET})
    assert config.write_token({"MY_TOKEN": SECRET}) == SECRET
    assert config.write_token({"MY_TOKEN": ""}) is None
    assert config.write_token({}) is None
    for shown in (repr(config), str(config), config.model_dump_json()):
        assert SECRET not in shown


def test_write_token_default_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PKWBUS_WRITE_TOKEN", SECRET)
    config = parse(MINIMAL)
    assert config.write_token() == SECRET
    assert SECRET not in repr(config)
    monkeypatch.delenv("PKWBUS_WRITE_TOKEN")
    assert config.write_token() is None


def test_token_never_in_errors(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PKWBUS_WRITE_TOKEN", SECRET)
    with pytest.raises(ConfigError) as caught:
        parse_config("lines: 3", catalogs=FAKE)
    assert SECRET not in str(caught.value)
    assert SECRET not in repr(caught.value)


def test_config_is_immutable() -> None:
    config = parse(MINIMAL)
    with pytest.raises(ValueError):
        config.lines[0].baudrate = 9600  # type: ignore[misc]


# --------------------------------------------------------------- fuzzing


KEYS = [
    "listen", "api", "audit_db", "log_format", "lines", "name", "port", "protocol",
    "baudrate", "parity", "timeout", "retries", "drives", "address", "dialect", "poll",
    "parameter", "every", "writable", "parameters", "catalog", "type", "scale", "index",
    "pkw_words", "fc_address_format", "sim://fc?drives=1", "16-13", "r0021[2]",
]  # fmt: skip
SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([*KEYS, "fc", "uss", "1s", "-1ms", "E", "1-31", "variable", "[::1]:1"]),
    st.text(max_size=12),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: (
        st.lists(inner, max_size=4)
        | st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=5), inner, max_size=5)
    ),
    max_leaves=30,
)


@functools.cache
def _demo_tree() -> dict[str, Any]:
    loaded = yaml.safe_load(DEMO.read_text())
    assert isinstance(loaded, dict)
    return loaded


def _valid_tree() -> dict[str, Any]:
    """The demo configuration as a tree of its own (read once: YAML is slow to parse)."""
    return copy.deepcopy(_demo_tree())


def _mutate(tree: Any, path: Sequence[int], value: Any) -> Any:
    """Replace the node reached by following ``path`` (indices modulo size) with ``value``."""
    if not path or not isinstance(tree, dict | list) or not tree:
        return value
    keys = list(tree) if isinstance(tree, dict) else list(range(len(tree)))
    key = keys[path[0] % len(keys)]
    copy: Any = dict(tree) if isinstance(tree, dict) else list(tree)
    copy[key] = _mutate(tree[key], path[1:], value)
    return copy


@settings(max_examples=150, suppress_health_check=[HealthCheck.too_slow])
@given(VALUES)
def test_random_mappings_only_ever_raise_config_error(tree: Any) -> None:
    try:
        parse(yaml.safe_dump(tree))
    except ConfigError as exc:
        assert exc.problems and all(isinstance(p, str) and p for p in exc.problems)


@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.integers(0, 50), max_size=7), VALUES)
def test_mutated_demo_only_ever_raises_config_error(path: list[int], value: Any) -> None:
    tree = _mutate(_valid_tree(), path, value)
    try:
        parse(yaml.safe_dump(tree))
    except ConfigError as exc:
        assert exc.problems and all(isinstance(p, str) and p for p in exc.problems)


@settings(max_examples=200)
@given(st.text(alphabet=st.sampled_from("ab:-[]{},&*!|>'\"#?% \n\t0123456789.ms"), max_size=60))
def test_garbage_text_only_ever_raises_config_error(text: str) -> None:
    try:
        parse(text)
    except ConfigError as exc:
        assert exc.problems


@pytest.mark.parametrize(("given", "kept"), [("auto", "auto"), ("off", "off"), ("false", "off")])
def test_describe_is_auto_or_off_on_a_line_and_a_drive(given: str, kept: str) -> None:
    """A bare YAML ``off`` reads as false: it means off."""
    text = MINIMAL.replace("    drives:\n", f"    describe: {given}\n    drives:\n", 1)
    (line,) = parse(text).lines
    assert line.describe == kept
    assert all(d.describe is None for d in line.drives)


def test_describe_takes_no_other_word() -> None:
    text = MINIMAL.replace("    drives:\n", "    describe: sometimes\n    drives:\n", 1)
    (problem,) = problems_of(text)
    assert problem.startswith("lines[0].describe: must be auto or off")
