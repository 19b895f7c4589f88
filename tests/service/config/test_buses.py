"""Lines and drives per bus: each line of its bus's class with drives of the same bus, the
values the file gives, and a setting of another bus refused with the bus it applies to."""

from __future__ import annotations

import pytest

from pkwbus.catalog.dp_settings import DpSettings
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.dialects import IndLayout
from pkwbus.protocol.profibus.dpv1.msac import Dpv1Setup
from pkwbus.protocol.serial.telegram import BlockShape, FcAddressFormat
from pkwbus.service.config import (
    DriveBase,
    FcDrive,
    FcLine,
    LineBase,
    ProfibusDrive,
    ProfibusLine,
    UssDrive,
    UssLine,
)
from pkwbus.service.config.model import LINES
from pkwbus.service.config.serial import DP_DRIVE_KEYS, DP_LINE_KEYS
from tests.service.config.test_config import parse, problems_of, with_drive

THREE_BUSES = """
listen: 127.0.0.1:9100
lines:
  - name: fc_line
    port: /dev/ttyUSB0
    protocol: fc
    baudrate: 9600
    fc_address_format: 1-31
    parity: n
    stopbits: 2
    timeout: 250ms
    retries: 3
    pause: 2ms
    echo: true
    low_latency: true
    describe: off
    drives:
      - name: fan
        address: 31
        ind_layout: profidrive
        catalog: danfoss-fc
        poll: [{parameter: "16-13", every: 1s, unit: Hz}]
        writable: ["3-41"]
      - {name: pump, address: 2, alarms: off}
  - name: uss_line
    port: socket://gateway:4001
    protocol: uss
    baudrate: 19200
    inter_char_timeout: 3ms
    response_delay: 10ms
    alarms: off
    drives:
      - name: conveyor
        address: 0
        dialect: profidrive
        pkw_words: 3
        pzd_words: 6
        catalog: siemens-g120
        poll: [{parameter: r0021, every: 500ms}]
      - {name: press, address: 30, pkw_words: variable}
  - name: dp_line
    port: /dev/ttyUSB1
    protocol: profibus
    baudrate: 93750
    master_address: 3
    slot_time: 9ms
    watchdog: 2s
    retries: 4
    drives:
      - name: mixer
        address: 8
        dialect: danfoss-pcv
        ppo: 2
        ident: 0x0402
        cfg: "F3 F5"
        user_prm: [1, 2]
        catalog: danfoss-fc
        poll: [{parameter: "16-13", every: 1s}]
      - name: hoist
        address: 9
        ident: 0x80B5
        ppo: 3
        dpv1: true
        parameter_access: ds47
        axis: 1
        poll: [{parameter: r0021, every: 2s}]
"""


def test_each_line_and_its_drives_are_of_its_bus() -> None:
    fc, uss, dp = parse(THREE_BUSES).lines
    assert type(fc) is FcLine and all(type(d) is FcDrive for d in fc.drives)
    assert type(uss) is UssLine and all(type(d) is UssDrive for d in uss.drives)
    assert type(dp) is ProfibusLine and all(type(d) is ProfibusDrive for d in dp.drives)
    for line in (fc, uss, dp):
        assert isinstance(line, LineBase) and line.drive_class() is type(line.drives[0])
        assert all(isinstance(d, DriveBase) and d.protocol is line.protocol for d in line.drives)
    assert (fc.protocol, uss.protocol, dp.protocol) == (
        Bus.FC,
        Bus.USS,
        Bus.PROFIBUS,
    )
    assert {p: c.__name__ for p, c in LINES.items()} == {
        Bus.FC: "FcLine", Bus.USS: "UssLine", Bus.PROFIBUS: "ProfibusLine",
    }  # fmt: skip


def test_a_file_of_three_buses_has_the_values_it_had_with_one_line_model() -> None:
    """The values the configuration had when every line and drive was of one class."""
    config = parse(THREE_BUSES)
    assert str(config.listen) == "127.0.0.1:9100"
    fc, uss, dp = config.lines
    # The FC line and its drives.
    assert (fc.name, fc.port, fc.baudrate, fc.parity, fc.stopbits) == (
        "fc_line", "/dev/ttyUSB0", 9600, "N", 2,
    )  # fmt: skip
    assert (fc.timeout, fc.retries, fc.pause, fc.inter_char_timeout, fc.response_delay) == (
        0.25, 3, 0.002, None, None,
    )  # fmt: skip
    assert (fc.echo, fc.low_latency, fc.rs485, fc.describe, fc.alarms) == (
        True, True, None, "off", "auto",
    )  # fmt: skip
    assert fc.fc_address_format is fc.address_format is FcAddressFormat.RANGE_1_31
    assert (fc.address_range, fc.sim, fc.bits_per_character) == ((1, 31), None, 11)
    assert (fc.pause_seconds, fc.response_delay_seconds) == (0.002, None)
    assert fc.inter_char_seconds == pytest.approx(0.02291666666666667)
    fan, pump = fc.drives
    assert (fan.name, fan.address, fan.dialect, fan.catalog, fan.describe, fan.alarms) == (
        "fan", 31, None, "danfoss-fc", None, None,
    )  # fmt: skip
    assert (fan.pkw_dialect.name, fan.ind_layout, fan.layout) == (
        "fc", IndLayout.PROFIDRIVE, IndLayout.PROFIDRIVE,
    )  # fmt: skip
    assert fan.shape == BlockShape(4, 2)
    assert [(str(p.ref), p.every, p.unit) for p in fan.poll] == [("16-13", 1.0, "Hz")]
    assert [str(ref) for ref in fan.writable] == ["3-41"]
    assert (pump.address, pump.alarms, pump.layout, pump.shape) == (
        2, "off", IndLayout.USS, BlockShape(4, 2),
    )  # fmt: skip
    # The USS line and its drives.
    assert (uss.name, uss.port, uss.baudrate, uss.parity, uss.stopbits) == (
        "uss_line", "socket://gateway:4001", 19200, "E", 1,
    )  # fmt: skip
    assert (uss.timeout, uss.retries, uss.inter_char_timeout, uss.response_delay) == (
        0.1, 2, 0.003, 0.01,
    )  # fmt: skip
    assert (uss.describe, uss.alarms, uss.address_format, uss.address_range) == (
        "auto", "off", FcAddressFormat.RANGE_1_126, (0, 30),
    )  # fmt: skip
    assert (uss.inter_char_seconds, uss.response_delay_seconds) == (0.003, 0.01)
    assert uss.pause_seconds == pytest.approx(0.0020052083333333332)
    conveyor, press = uss.drives
    assert (conveyor.address, conveyor.dialect, conveyor.catalog) == (
        0, "profidrive", "siemens-g120",
    )  # fmt: skip
    assert (conveyor.pkw_dialect.name, conveyor.ind_layout, conveyor.layout) == (
        "profidrive", None, IndLayout.PROFIDRIVE,
    )  # fmt: skip
    assert (conveyor.pkw_words, conveyor.pzd_words, conveyor.sent_pkw_words) == (3, 6, 3)
    assert conveyor.shape == BlockShape(3, 6)
    assert [(str(p.ref), p.every) for p in conveyor.poll] == [("r0021", 0.5)]
    assert (press.address, press.pkw_dialect.name, press.layout) == (30, "uss", IndLayout.USS)
    assert (press.pkw_words, press.pzd_words, press.sent_pkw_words) == (None, 2, None)
    assert press.shape == BlockShape(None, 2)
    # The DP line and its slaves.
    assert (dp.name, dp.port, dp.baudrate, dp.parity, dp.stopbits, dp.retries) == (
        "dp_line", "/dev/ttyUSB1", 93750, "E", 1, 4,
    )  # fmt: skip
    assert (dp.master_address, dp.slot_time, dp.watchdog) == (3, pytest.approx(0.009), 2.0)
    assert (dp.address_format, dp.address_range) == (FcAddressFormat.RANGE_1_126, (0, 125))
    assert (dp.describe, dp.alarms, dp.inter_char_seconds) == ("auto", "auto", 0.005)
    assert dp.pause_seconds == pytest.approx(0.00041066666666666666)
    mixer, hoist = dp.drives
    assert (mixer.address, mixer.dialect, mixer.catalog, mixer.pkw_dialect.name) == (
        8, "danfoss-pcv", "danfoss-fc", "danfoss-pcv",
    )  # fmt: skip
    assert (mixer.ppo, mixer.ident, mixer.gsd, mixer.cfg, mixer.user_prm) == (
        2, 0x0402, None, b"\xf3\xf5", b"\x01\x02",
    )  # fmt: skip
    assert (mixer.dpv1, mixer.parameter_access, mixer.axis, mixer.access) == (
        None, None, None, "pkw",
    )  # fmt: skip
    assert (mixer.layout, mixer.shape) == (IndLayout.PROFIDRIVE, BlockShape(4, 6))
    settings, problems = mixer.dp.settings()
    assert problems == [] and isinstance(settings, DpSettings)
    assert (settings.ident, settings.cfg, settings.user_prm, settings.dpv1) == (
        0x0402, b"\xf3\xf5", b"\x01\x02", None,
    )  # fmt: skip
    assert settings.ppo.number == 2
    assert (hoist.ppo, hoist.ident, hoist.cfg, hoist.user_prm, hoist.pkw_dialect.name) == (
        3, 0x80B5, None, None, "profidrive",
    )  # fmt: skip
    assert (hoist.dpv1, hoist.parameter_access, hoist.axis, hoist.access) == (
        True, "ds47", 1, "ds47",
    )  # fmt: skip
    assert hoist.shape == BlockShape(0, 2)
    settings, problems = hoist.dp.settings()
    assert problems == [] and settings is not None
    assert (settings.ident, settings.cfg, settings.user_prm, settings.ppo.number) == (
        0x80B5, b"\xf1", b"", 3,
    )  # fmt: skip
    assert settings.dpv1 == Dpv1Setup(max_data=240, response_timeout=1.0, read_write=True)
    assert [(str(p.ref), p.every) for p in hoist.poll] == [("r0021", 2.0)]


# ------------------------------------------- settings of another bus, refused


def test_a_dp_setting_on_an_fc_drive_is_refused_as_before() -> None:
    assert problems_of(with_drive("{name: a, address: 1, gsd: x.gsd}")) == [
        "lines[0].drives[0].gsd: applies to protocol profibus only"
    ]


@pytest.mark.parametrize("protocol", ["fc", "uss"])
def test_every_dp_setting_of_a_drive_is_refused_off_profibus(protocol: str) -> None:
    drive = (
        "{name: a, address: 1, ppo: 1, ident: 1, gsd: g, cfg: 'F3', user_prm: '00', dpv1: true,"
        " parameter_access: pkw, axis: 1}"
    )
    assert problems_of(with_drive(drive, protocol)) == [
        f"lines[0].drives[0].{key}: applies to protocol profibus only"
        for key in ("ppo", "ident", "gsd", "cfg", "user_prm", "dpv1", "parameter_access", "axis")
    ]


@pytest.mark.parametrize(
    ("protocol", "line", "drive", "expected"),
    [
        ("fc", "", "{name: a, address: 1, pkw_words: 4, pzd_words: 2}", [
            "lines[0].drives[0].pkw_words: applies to protocol uss only: FC telegrams have a"
            " fixed shape",
            "lines[0].drives[0].pzd_words: applies to protocol uss only: FC telegrams have a"
            " fixed shape",
        ]),
        ("profibus", "", "{name: a, address: 8, ident: 0x0402, pkw_words: 4, pzd_words: 2,"
         " ind_layout: uss}", [
            "lines[0].drives[0].pkw_words: the PPO sets it over PROFIBUS: give ppo",
            "lines[0].drives[0].pzd_words: the PPO sets it over PROFIBUS: give ppo",
            "lines[0].drives[0].ind_layout: the PPO sets it over PROFIBUS: give ppo",
        ]),
        ("fc", "    master_address: 3\n    slot_time: 5ms\n    watchdog: 1s\n",
         "{name: a, address: 1}", [
            "lines[0].master_address: applies to protocol profibus only",
            "lines[0].slot_time: applies to protocol profibus only",
            "lines[0].watchdog: applies to protocol profibus only",
        ]),
        ("uss", "    master_address: 3\n    fc_address_format: 1-31\n", "{name: a, address: 1}", [
            "lines[0].fc_address_format: applies to protocol fc only",
            "lines[0].master_address: applies to protocol profibus only",
        ]),
        ("profibus", "    fc_address_format: 1-31\n", "{name: a, address: 8, ident: 0x0402}",
         ["lines[0].fc_address_format: applies to protocol fc only"]),
        ("fc", "", "{name: a, address: 200, gsd: x.gsd, ppo: 2}", [
            "lines[0].drives[0].address: 200 is outside 1-126 for protocol fc",
            "lines[0].drives[0].ppo: applies to protocol profibus only",
            "lines[0].drives[0].gsd: applies to protocol profibus only",
        ]),
        ("fc", "", "{name: a, address: x, protocol: fc}", [
            "lines[0].drives[0].address: must be a whole number, not 'x'",
            "lines[0].drives[0].protocol: is the line's setting: give the protocol once, on the"
            " line",
        ]),
    ],
)  # fmt: skip
def test_settings_of_another_bus_are_refused_as_before(
    protocol: str, line: str, drive: str, expected: list[str]
) -> None:
    """The problems, and their order, of the one line model (which took every setting)."""
    assert problems_of(with_drive(drive, protocol, line)) == expected


def test_a_refused_setting_is_told_with_the_problems_of_the_fields() -> None:
    found = problems_of(with_drive("{name: a, address: 1, gsd: x.gsd}", line="    parity: Q\n"))
    assert found == [
        "lines[0].parity: must be 'E', 'O' or 'N', not 'Q'",
        "lines[0].drives[0].gsd: applies to protocol profibus only",
    ]


def test_each_bus_refuses_the_settings_of_the_others() -> None:
    """Every setting a line or drive of one bus takes and another's does not is refused
    there with a message, never as an unknown key."""
    drives = {line.drive_class() for line in LINES.values()}
    for kinds in (set(LINES.values()), drives):
        for one in kinds:
            for other in kinds - {one}:
                missing = other.model_fields.keys() - one.model_fields.keys()
                assert missing <= one.refused_keys.keys(), (one.__name__, other.__name__)
    assert set(DP_LINE_KEYS) == ProfibusLine.model_fields.keys() - LineBase.model_fields.keys()
    assert set(DP_DRIVE_KEYS) == ProfibusDrive.model_fields.keys() - DriveBase.model_fields.keys()


# ------------------------------------------------------- the line's protocol


@pytest.mark.parametrize(
    ("protocol", "expected"),
    [
        ("modbus", "lines[0].protocol: must be 'fc', 'uss' or 'profibus', not 'modbus'"),
        ("FC", "lines[0].protocol: must be 'fc', 'uss' or 'profibus', not 'FC'"),
        ("[fc]", "lines[0].protocol: must be 'fc', 'uss' or 'profibus', not a list"),
        ("7", "lines[0].protocol: must be 'fc', 'uss' or 'profibus', not 7"),
    ],
)
def test_an_unknown_protocol_names_the_known_ones(protocol: str, expected: str) -> None:
    assert problems_of(with_drive("{name: a, address: 1}", protocol)) == [expected]


def test_a_line_without_protocol_or_not_a_mapping() -> None:
    text = (
        "lines: [{name: l1, port: /dev/ttyUSB0, baudrate: 19200, drives: [{name: a, address: 1}]}]"
    )
    assert problems_of(text) == ["lines[0].protocol: is required"]
    assert problems_of("lines: [3]") == ["lines[0]: must be a mapping (key: value), not 3"]
    assert problems_of("lines: [[1]]") == ["lines[0]: must be a mapping (key: value), not a list"]


def test_an_unknown_key_is_answered_with_the_settings_of_its_bus() -> None:
    dp = with_drive("{name: a, address: 8, ident: 0x0402, gds: x}", "profibus")
    assert problems_of(dp) == ["lines[0].drives[0].gds: is not a known setting; did you mean gsd?"]
    (problem,) = problems_of(with_drive("{name: a, address: 1}", "fc", "    slot: 1ms\n"))
    assert problem.startswith("lines[0].slot: is not a known setting (known: name, port,")
    assert "slot_time" not in problem and "fc_address_format" in problem
