"""One name per parameter on each configured drive, whatever spelling the file uses."""

from __future__ import annotations

import pytest

from pkwbus.protocol.values import parse_parameter
from pkwbus.service.config import ConfigError, parse_config


def drive_yaml(protocol: str, drive: str) -> str:
    return f"""
lines:
  - name: l1
    port: /dev/ttyUSB0
    protocol: {protocol}
    baudrate: 19200
    drives:
      - {drive}
"""


def problems(text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, environ={})
    return caught.value.problems


def test_fc_names_in_any_spelling_are_the_drive_s_one_name() -> None:
    text = drive_yaml(
        "fc",
        "{name: fan, address: 1, catalog: danfoss-fc, "
        "poll: [{parameter: '1613', every: 1s}, {parameter: '16-14', every: 1s}], "
        "writable: ['0341', '3-42']}",
    )
    drive = parse_config(text, environ={}).lines[0].drives[0]
    assert [drive.canonical(p.ref).name for p in drive.poll] == ["16-13", "16-14"]
    assert [drive.canonical(r).name for r in drive.writable] == ["3-41", "3-42"]


def test_siemens_notation_on_an_fc_drive_names_the_fc_form() -> None:
    text = drive_yaml("fc", "{name: fan, address: 1, writable: ['3-42', 'p0341']}")
    [problem] = problems(text)
    assert problem.startswith("lines[0].drives[0].writable[1]: p0341: r/p is Siemens notation")
    assert problem.endswith("write 3-41")


def test_a_siemens_drive_takes_the_catalog_s_prefix_else_the_file_s() -> None:
    text = drive_yaml(
        "uss",
        "{name: pump, address: 1, catalog: siemens-g120, "
        "poll: [{parameter: '21', every: 1s}, {parameter: 'P2000', every: 1s}], "
        "writable: ['1120']}",
    )
    drive = parse_config(text, environ={}).lines[0].drives[0]
    assert [drive.canonical(p.ref).name for p in drive.poll] == ["r0021", "p2000"]
    assert drive.canonical(drive.writable[0]).name == "p1120"
    assert drive.canonical(parse_parameter("3000")).name == "3000"  # known to neither


def test_one_parameter_written_r_and_p_is_a_problem() -> None:
    text = drive_yaml(
        "uss", "{name: pump, address: 1, poll: [{parameter: r2000, every: 1s}], writable: [p2000]}"
    )
    assert problems(text) == [
        "lines[0].drives[0].writable[0]: p2000 and r2000 name one parameter: write it one way"
    ]


def test_a_read_only_parameter_by_its_catalog_is_not_writable() -> None:
    text = drive_yaml("uss", "{name: pump, address: 1, catalog: siemens-g120, writable: ['21']}")
    assert problems(text) == ["lines[0].drives[0].writable[0]: 21 is r0021, read-only (r)"]
