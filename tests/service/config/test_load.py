"""The line load estimate and the check-config report."""

from __future__ import annotations

from pathlib import Path

import pytest

from pkwbus.protocol.buses import Bus
from pkwbus.service.config import Config, load_config
from pkwbus.service.config.line_load import (
    check_config_report,
    config_load,
    exchange_seconds,
    line_load,
    port_warnings,
    telegram_bytes,
)
from tests.service.config.test_config import DEMO, FAKE, parse

BY_ID = "/dev/serial/by-id/usb-FTDI_USB-RS485_Cable_FT1ABCDE-if00-port0"


def fc_line(polls: str, baud: int = 9600, extra: str = "", port: str = BY_ID) -> Config:
    return parse(
        f"""
lines:
  - name: l1
    port: {port}
    protocol: fc
    baudrate: {baud}
{extra}    drives:
      - name: fan
        address: 1
        catalog: danfoss-fc
        alarms: off  # the figures below are of the polls given
        counters: off
        poll: {polls}
"""
    )


def test_the_alarm_words_polled_by_default_count_in_the_estimate() -> None:
    from pkwbus.service.config.default_polls import ALARM_EVERY

    polls = '[{parameter: "16-13", every: 1s}, {parameter: "16-90", every: 500ms}]'
    given = line_load(fc_line(polls).lines[0])
    auto = (
        fc_line(polls)
        .lines[0]
        .model_copy(
            update={
                "drives": [fc_line(polls).lines[0].drives[0].model_copy(update={"alarms": "auto"})]
            }
        )
    )
    counted = line_load(auto)
    # 16-90 is polled already; 16-92 (the warning word) is added, every ALARM_EVERY seconds.
    assert counted.exchanges_per_second == pytest.approx(
        given.exchanges_per_second + 1 / ALARM_EVERY
    )


def test_fc_line_against_a_hand_computed_figure() -> None:
    config = fc_line(
        '[{parameter: "16-13", every: 1s}, {parameter: "16-14", every: 1s},'
        ' {parameter: "16-90", every: 500ms}]'
    )
    # 9600 baud, 8E1 = 11 bits a character; FC parameter telegram 16 bytes each way;
    # pause 3.5 characters; response delay 5 ms (the default).
    character = 11 / 9600
    exchange = (16 + 16) * character + 3.5 * character + 0.005
    assert exchange == pytest.approx(0.0456771, abs=1e-7)
    polls_per_second = 1 / 1 + 1 / 1 + 1 / 0.5
    load = line_load(config.lines[0])
    assert load.line == "l1"
    assert (load.protocol, load.baudrate, load.drives) == (Bus.FC, 9600, 1)
    assert load.exchange_seconds == {"fan": pytest.approx(exchange)}
    assert load.exchanges_per_second == pytest.approx(polls_per_second)
    assert load.utilisation == pytest.approx(exchange * polls_per_second)
    assert load.utilisation == pytest.approx(0.1827083, abs=1e-6)
    assert load.capacity == pytest.approx(1 / exchange)
    assert load.warnings == []


def test_uss_telegram_sizes_and_configured_timing() -> None:
    config = parse(
        """
lines:
  - name: u
    port: /dev/ttyUSB0
    protocol: uss
    baudrate: 19200
    parity: N
    pause: 2ms
    response_delay: 10ms
    drives:
      - {name: a, address: 1, poll: [{parameter: r0021, every: 1s}]}
      - {name: b, address: 2, pkw_words: 3, pzd_words: 0, poll: [{parameter: r0021, every: 2s}]}
      - {name: c, address: 3, pkw_words: variable, pzd_words: 6}
"""
    )
    line = config.lines[0]
    a, b, c = line.drives
    assert [telegram_bytes(line, d) for d in (a, b, c)] == [16, 10, 24]
    character = 10 / 19200  # parity N: start, 8 data, stop
    expected_a = 2 * 16 * character + 0.002 + 0.010
    expected_b = 2 * 10 * character + 0.002 + 0.010
    assert exchange_seconds(line, a) == pytest.approx(expected_a)
    assert exchange_seconds(line, b) == pytest.approx(expected_b)
    load = line_load(line)
    assert load.exchanges_per_second == pytest.approx(1.5)
    assert load.utilisation == pytest.approx(expected_a + expected_b / 2)
    assert load.capacity == pytest.approx(1.5 / (expected_a + expected_b / 2))


def test_simulator_response_delay_counts_when_the_line_has_none() -> None:
    config = load_config(DEMO, environ={}, catalogs=FAKE)
    fc = config.lines[0]
    character = 11 / 19200
    assert exchange_seconds(fc, fc.drives[0]) == pytest.approx(
        32 * character + 3.5 * character + 0.003
    )
    assert [load.line for load in config_load(config)] == ["fc_line", "uss_line", "dp_line"]


def test_line_without_polls_has_a_capacity_and_no_load() -> None:
    config = fc_line("[]")
    load = line_load(config.lines[0])
    assert (load.exchanges_per_second, load.utilisation) == (0, 0)
    assert load.capacity == pytest.approx(
        1 / exchange_seconds(config.lines[0], config.lines[0].drives[0])
    )


def test_warning_above_80_percent() -> None:
    # 20 exchanges/s of 45.68 ms each: 91 % of a 9600 baud line.
    polls = '[{parameter: "16-13", every: 100ms}, {parameter: "16-14", every: 100ms}]'
    load = line_load(fc_line(polls).lines[0])
    assert load.utilisation == pytest.approx(20 * 0.0456771, abs=1e-5)
    (warning,) = load.warnings
    assert warning.startswith("line l1: utilisation 91% is above 80%")


def test_no_warning_at_the_same_demand_on_a_faster_line() -> None:
    polls = '[{parameter: "16-13", every: 100ms}, {parameter: "16-14", every: 100ms}]'
    load = line_load(fc_line(polls, baud=115200).lines[0])
    assert load.utilisation < 0.8
    assert load.warnings == []


def test_overload_says_polls_will_run_late() -> None:
    polls = '[{parameter: "16-13", every: 20ms}]'
    (warning,) = line_load(fc_line(polls).lines[0]).warnings
    assert "more than the 21.9 the line can carry" in warning
    assert "50.0 exchanges/s" in warning


def test_report_of_the_demo() -> None:
    config = load_config(DEMO, environ={}, catalogs=FAKE)
    report = check_config_report(config, catalogs=FAKE)
    assert report[0] == "listen 127.0.0.1:9725, audit log var/audit.sqlite"
    assert report[1].startswith("line fc_line: fc at 19200 baud, 3 drives, ")
    assert any(r.startswith("line uss_line: uss at 38400 baud, 2 drives, ") for r in report)
    assert not any(r.startswith("WARN") for r in report)
    # r0032 (active power) is missing from the stand-in siemens-g120 catalog.
    assert report[-1] == (
        "NOTE lines[1].drives[0].poll[3]: r0032 is not in catalog siemens-g120: "
        "it is read and exported as its raw number"
    )


def test_report_lines_and_warnings() -> None:
    polls = (
        '[{parameter: "16-13", every: 100ms}, {parameter: "16-14", every: 100ms},'
        ' {parameter: "16-17", every: 1s}, {parameter: "16-18", every: 1s, type: u16}]'
    )
    report = check_config_report(fc_line(polls), catalogs=FAKE)
    assert report[1] == (
        "line l1: fc at 9600 baud, 1 drives, 22.00 polls/s, utilisation 100.5% "
        "(capacity 22 exchanges/s)"
    )
    # The drive's alarm log (15-30..15-32, its catalog's) is watched: its newest entry's
    # code and time every 10 s, 2 telegrams of 16 bytes each way at 9600 baud 8E1, with
    # the pause of 3.5 characters and the drive's 5 ms: 0.91 % of the line's time.
    exchange = (2 * 16 * 11 + 3.5 * 11) / 9600 + 0.005
    assert f"{2 * exchange / 10:.2%}" == "0.91%"
    # Its 14 settings (the danfoss-fc catalog's) swept each hour, one telegram each: the
    # line before the watch's.
    assert report[2] == (
        f"  14 setting(s) of 1 drive(s) swept (settings): {14 * exchange / 3600:.2%} of the"
        " line's time, after the polls"
    )
    assert report[3] == (
        f"  the own logs of 1 drive(s) watched (events): {2 * exchange / 10:.2%} of the"
        " line's time, after the polls"
    )
    assert report[4].startswith("WARN line l1: polls demand 22.0 exchanges/s")
    assert report[5:] == [
        "NOTE lines[0].drives[0].poll[2]: 16-17 is not in catalog danfoss-fc: "
        "it is read and exported as its raw number",
        "NOTE lines[0].drives[0].poll[3]: 16-18 is not in catalog danfoss-fc: "
        "the config's type and scaling apply",
    ]


def test_report_notes_drives_without_catalog() -> None:
    config = parse(
        """
lines:
  - name: l1
    port: socket://gateway:4001
    protocol: fc
    baudrate: 19200
    drives:
      - {name: a, address: 1, poll: [{parameter: "16-13", every: 1s}]}
"""
    )
    assert check_config_report(config, catalogs=FAKE)[-1] == (
        "NOTE lines[0].drives[0]: drive a has no catalog: 16-13 are exported as raw numbers"
    )


POLL_ONE = '[{parameter: "16-13", every: 1s}]'


@pytest.mark.parametrize("port", ["/dev/ttyUSB0", "/dev/ttyACM3"])
def test_kernel_numbered_port_gets_a_warning_naming_by_id(port: str, tmp_path: Path) -> None:
    config = fc_line(POLL_ONE, port=port)
    report = check_config_report(config, catalogs=FAKE, dev=tmp_path)
    warnings = [r for r in report if r.startswith("WARN")]
    assert warnings == [
        f"WARN line l1: port {port} is numbered by the kernel in the order it finds adapters"
        " and may name another adapter after a replug or a reboot: use its"
        " /dev/serial/by-id/... name (pkwbus ports lists them)"
    ]


def test_the_warning_names_the_by_id_link_of_this_machine(tmp_path: Path) -> None:
    links = tmp_path / "serial" / "by-id"
    links.mkdir(parents=True)
    (links / "usb-FTDI_FT232R_A10K1234-if00-port0").symlink_to("/dev/ttyUSB0")
    (links / "usb-other-if00-port0").symlink_to("/dev/ttyUSB1")
    (warning,) = port_warnings(fc_line(POLL_ONE, port="/dev/ttyUSB0").lines[0], dev=tmp_path)
    assert warning.endswith(f": use {links}/usb-FTDI_FT232R_A10K1234-if00-port0")


@pytest.mark.parametrize(
    "port", [BY_ID, "/dev/ttyS0", "/dev/ttyAMA0", "socket://gw:4001", "sim://fc?drives=1"]
)
def test_stable_ports_get_no_warning(port: str, tmp_path: Path) -> None:
    report = check_config_report(fc_line(POLL_ONE, port=port), catalogs=FAKE, dev=tmp_path)
    assert not [r for r in report if r.startswith("WARN")]
