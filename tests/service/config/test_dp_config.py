"""PROFIBUS DP lines in the configuration: every mistake a placed error, exit 2, nothing sent."""

from __future__ import annotations

from pathlib import Path

import pytest

from pkwbus.cli import main
from pkwbus.protocol.buses import Bus
from pkwbus.service.config import ConfigError, load_config, parse_config

BAD = Path(__file__).parent / "bad_dp_configs"

EXPECTED = {
    "ppo_without_pkw": "lines[0].drives[0].ppo: PPO 3 has no PKW words",
    "writable_ppo_without_pkw": "lines[0].drives[0].ppo: PPO 4 has no PKW words",
    "address_range": "lines[0].drives[0].address: 126 is outside 0-125 for protocol profibus",
    "address_master": "lines[0].drives[0].address: 3 is the master's own station",
    "gsd_missing": "lines[0].drives[0].gsd: cannot read ",
    "gsd_broken": "lines[0].drives[0].gsd: ",
    "ident_contradicts_gsd": (
        "lines[0].drives[0].ident: 0x0403 contradicts the GSD file's Ident_Number 0x0402"
    ),
    "dialect_fc": "lines[0].drives[0].dialect: fc is not for protocol profibus",
    "duplicate_address": "lines[0].drives[1].address: address 8 is already used by mixer",
    "no_ident": "lines[0].drives[0]: give the slave's ident number",
    "master_address_on_fc": "lines[0].master_address: applies to protocol profibus only",
    "ppo_on_uss": "lines[0].drives[0].ppo: applies to protocol profibus only",
    "parity_odd": "lines[0].parity: PROFIBUS characters are always 8E1",
    "cfg_mismatch": "lines[0].drives[0].cfg: F3 F5 sets up 20/20 bytes in/out; PPO 1 has 12",
    "bad_ident": "lines[0].drives[0].ident: 65536 is not a 16-bit number",
    "pkw_words_on_dp": "lines[0].drives[0].pkw_words: the PPO sets it over PROFIBUS",
    "bad_watchdog": "lines[0].watchdog: '1h' is too long for a watchdog",
    "gsd_rate_unsupported": (
        "lines[0].drives[0].gsd: the slave does not run at 93750 baud, the line's rate (its GSD"
        " file names 9600, 19200)"
    ),
    "gsd_slot_time_short": (
        "lines[0].drives[0].gsd: its GSD file's MaxTsdr at 19200 baud, 600 bit times (31.2 ms),"
        " is longer than the line's slot_time (20 ms)"
    ),
}

GOOD = """
lines:
  - name: dp
    port: /dev/ttyUSB1
    protocol: profibus
    baudrate: 93750
    slot_time: 8ms
    watchdog: 2s
    drives:
      - name: mixer
        address: 8
        dialect: danfoss-pcv
        gsd: {gsd}
        catalog: danfoss-fc
        poll: [{{parameter: "16-13", every: 1s}}]
      - name: pump
        address: 9
        ident: 0x80B5
        ppo: 3
"""


def test_every_broken_file_has_an_expectation() -> None:
    assert sorted(p.stem for p in BAD.glob("*.yaml")) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_broken_dp_file_names_its_place(name: str) -> None:
    with pytest.raises(ConfigError) as caught:
        load_config(BAD / f"{name}.yaml", environ={})
    problems = caught.value.problems
    assert any(p.startswith(EXPECTED[name]) for p in problems), problems
    for problem in problems:
        assert "Input should" not in problem and "Value error" not in problem


def test_a_broken_gsd_file_names_its_line() -> None:
    with pytest.raises(ConfigError) as caught:
        load_config(BAD / "gsd_broken.yaml", environ={})
    (problem,) = caught.value.problems
    assert "broken.gsd: GSD line 4: " in problem


@pytest.mark.parametrize("name", ["gsd_broken", "address_master", "ppo_without_pkw"])
def test_check_config_exits_2(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check-config", str(BAD / f"{name}.yaml")]) == 2
    err = capsys.readouterr().err
    assert EXPECTED[name] in err and "Traceback" not in err


def test_a_good_dp_line(tmp_path: Path) -> None:
    gsd = BAD / "gsd" / "drive.gsd"
    (tmp_path / "drive.gsd").write_bytes(gsd.read_bytes())
    path = tmp_path / "pkwbus.yaml"
    path.write_text(GOOD.format(gsd="drive.gsd"))  # relative to the configuration's folder
    config = load_config(path, environ={})
    line = config.lines[0]
    assert line.protocol is Bus.PROFIBUS
    assert (line.master_address, line.slot_time, line.watchdog) == (2, 0.008, 2.0)
    mixer, pump = line.drives
    settings, problems = mixer.dp.settings()
    assert problems == [] and settings is not None
    assert settings.ident == 0x0402 and settings.cfg == b"\xf3\xf1"
    assert settings.user_prm  # the GSD's user parameters with their defaults
    pump_settings, _ = pump.dp.settings()
    assert pump_settings is not None and pump_settings.ppo.number == 3
    assert pump.pkw_dialect.name == "profidrive"


VENDOR_SHAPED = Path(__file__).parents[2] / "protocol" / "profibus" / "gsd_files" / "mm4_like.gse"


def test_a_vendor_shaped_gsd_file_as_it_ships(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """The MICROMASTER-4-like file (baud rate lines, DP-V1 keys, module reference lines):
    its PPO 1 module, its user parameters, its DP-V1 services; check-config exit 0."""
    text = one_slave_line(f"{{name: a, address: 8, gsd: {VENDOR_SHAPED}, ppo: 1}}")
    settings, problems = parse_config(text, environ={}).lines[0].drives[0].dp.settings()
    assert problems == [] and settings is not None
    assert (settings.ident, settings.cfg, settings.user_prm) == (0x80B5, b"\xf3\xf1", bytes(3))
    assert settings.module is not None and settings.module.reference == 21
    assert settings.dpv1 is not None and settings.dpv1.max_data == 240
    ppo3 = one_slave_line(f"{{name: a, address: 8, gsd: {VENDOR_SHAPED}, ppo: 3}}")
    found, _ = parse_config(ppo3, environ={}).lines[0].drives[0].dp.settings()
    assert found is not None and found.cfg == b"\x00\xf1"  # an empty slot before the PZD
    path = tmp_path / "pkwbus.yaml"
    path.write_text(text.replace("93750", "19200"))
    assert main(["check-config", str(path)]) == 0, capsys.readouterr().err


def test_cfg_given_needs_no_module_of_the_gsd_file(tmp_path: Path) -> None:
    """The configuration's cfg overrides the GSD file's: a file without a module for the
    PPO is refused only where no cfg is given (docs/profibus.md)."""
    gsd = tmp_path / "telegrams.gsd"
    gsd.write_text(
        "#Profibus_DP\nIdent_Number = 0x0402\nUser_Prm_Data = 0x01\n"
        'Module = "Standard Telegram 1" 0x00,0xE1,0xD1\n1\nEndModule\n'
    )
    without = one_slave_line(f"{{name: a, address: 8, gsd: {gsd}}}")
    with pytest.raises(ConfigError) as caught:
        parse_config(without, environ={})
    assert "has no module for PPO 1 (modules: 'Standard Telegram 1'); give cfg" in str(caught.value)
    given = one_slave_line(f'{{name: a, address: 8, gsd: {gsd}, cfg: "F3 F1"}}')
    settings, problems = parse_config(given, environ={}).lines[0].drives[0].dp.settings()
    assert problems == [] and settings is not None
    assert (settings.ident, settings.cfg, settings.user_prm) == (0x0402, b"\xf3\xf1", b"\x01")
    assert settings.module is None


def test_the_slot_time_waits_for_the_slowest_slaves_max_tsdr(tmp_path: Path) -> None:
    from pkwbus.protocol.profibus.fdl import timing as dp_timing

    slow = BAD / "gsd" / "slow.gsd"
    assert dp_timing.default_slot_time(19200, 60) == dp_timing.default_slot_time(19200)
    longer = dp_timing.default_slot_time(19200, 600)
    assert longer == pytest.approx(dp_timing.default_slot_time(19200) + 540 / 19200)
    text = one_slave_line(f"{{name: a, address: 8, gsd: {slow}}}").replace("93750", "19200")
    assert parse_config(text, environ={}).lines[0].drives[0].dp.settings()[0] is not None


def test_parse_config_without_a_folder_reads_gsd_paths_as_given() -> None:
    gsd = BAD / "gsd" / "drive.gsd"
    config = parse_config(GOOD.format(gsd=str(gsd)), environ={})
    assert config.lines[0].drives[0].dp.settings()[0] is not None


SIM_LINE = """
lines:
  - name: dp
    port: /dev/ttyUSB1
    protocol: profibus
    baudrate: {baud}
    drives:
      - name: a
        address: 8
        dialect: danfoss-pcv
        ident: 0x0402
        poll: [{{parameter: "16-13", every: {every}}}, {{parameter: "16-14", every: 1s}}]
      - {{name: b, address: 9, ident: 0x0402, dialect: danfoss-pcv, ppo: 2}}
"""


def test_check_config_estimates_the_dp_cycle_and_warns_of_polls_it_cannot_carry() -> None:
    from pkwbus.protocol.profibus.fdl import timing as dp_timing
    from pkwbus.service.config.line_load import DP_JOB_CYCLES, check_config_report, line_load

    config = parse_config(SIM_LINE.format(baud=19200, every="50ms"), environ={})
    load = line_load(config.lines[0])
    # PPO 1: 12 data bytes + 9 of the frame; PPO 2: 20 + 9, each way.
    expected = dp_timing.exchange_time(21, 21, 19200) + dp_timing.exchange_time(29, 29, 19200)
    assert load.cycle == pytest.approx(expected)
    assert load.capacity == pytest.approx(1 / (DP_JOB_CYCLES * expected))
    (warning,) = load.warnings
    assert "drive a's polls ask for 21.0 reads/s" in warning
    report = "\n".join(check_config_report(config))
    assert f"DP cycle {expected * 1000:.1f} ms" in report and "WARN" in report
    fast = parse_config(SIM_LINE.format(baud=93750, every="1s"), environ={})
    assert line_load(fast.lines[0]).warnings == []


DS47_LINE = """
lines:
  - name: dp
    port: /dev/ttyUSB1
    protocol: profibus
    baudrate: 19200
    drives:
      - name: a
        address: 8
        ident: 0x80B5
        ppo: 3
        dpv1: true
        poll: [{polls}]
      - {{name: b, address: 9, ident: 0x80B5}}
"""


def test_check_config_estimates_parameters_per_second_through_data_record_47() -> None:
    from pkwbus.protocol.profibus.fdl import timing as dp_timing
    from pkwbus.service.config.line_load import (
        DP_JOB_CYCLES,
        check_config_report,
        line_load,
        record_seconds,
    )

    polls = ", ".join(f'{{parameter: "r{n:04d}", every: 1s}}' for n in range(20, 40))
    config = parse_config(DS47_LINE.format(polls=polls), environ={})
    drive = config.lines[0].drives[0]
    assert drive.access == "ds47"  # PPO 3 has no PKW words; the slave is DP-V1
    load = line_load(config.lines[0])
    # PPO 3: 4 data bytes + 9 of the frame; PPO 1: 12 + 9, each way.
    cycle = dp_timing.exchange_time(13, 13, 19200) + dp_timing.exchange_time(21, 21, 19200)
    assert load.cycle == pytest.approx(cycle)
    # The MSAC_C1 frames: SD2 with both SAPs (11 bytes) around the data; a request of 20
    # value reads is 4 + 6 * 20 bytes, its response as long at most.
    write = dp_timing.exchange_time(11 + 4 + 124, 11 + 4, 19200)
    read = dp_timing.exchange_time(11 + 4, 11 + 4 + 124, 19200)
    assert record_seconds(drive, 20, 19200) == pytest.approx((write + read) / 2)
    access, most = load.access["a"]
    assert access == "ds47"
    assert most == pytest.approx(20 / (DP_JOB_CYCLES * (cycle + (write + read) / 2)))
    assert load.access["b"] == ("pkw", pytest.approx(1 / (DP_JOB_CYCLES * cycle)))
    assert most > load.access["b"][1]  # many parameters a request, one PKW job
    report = "\n".join(check_config_report(config))
    assert f"drive a: parameters through data record 47 (DP-V1), at most {most:.1f}" in report


def one_slave_line(drive: str) -> str:
    """A DP line at 93750 baud with ``drive`` (a flow mapping) as its one slave."""
    return f"""
lines:
  - name: dp
    port: /dev/ttyUSB1
    protocol: profibus
    baudrate: 93750
    drives:
      - {drive}
"""


@pytest.mark.parametrize(
    ("drive", "message"),
    [
        ("{name: a, address: 8, ident: 0x80B5, ppo: 3, parameter_access: ds47,"
         " poll: [{parameter: r0021, every: 1s}]}", "ds47 needs a DP-V1 slave"),
        ("{name: a, address: 8, ident: 0x80B5, ppo: 3, dpv1: true, parameter_access: pkw,"
         " poll: [{parameter: r0021, every: 1s}]}", "pkw: PPO 3 has no PKW words"),
        ("{name: a, address: 8, ident: 0x0B6A, ppo: 3, dpv1: true, dialect: hitachi-sjpb,"
         " poll: [{parameter: '1082', every: 1s}]}", "documents the PKW channel only"),
        ("{name: a, address: 8, ident: 0x80B5, axis: 1, poll: [{parameter: r0021, every: 1s}]}",
         "axis: applies to parameter_access: ds47 only"),
    ],
)  # fmt: skip
def test_data_record_47_mistakes_are_placed(drive: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_config(one_slave_line(drive), environ={})


def test_data_record_47_on_a_slave_without_record_services_or_with_text_polls(
    tmp_path: Path,
) -> None:
    gsd = tmp_path / "v1.gsd"
    gsd.write_text(
        "#Profibus_DP\nIdent_Number = 0x80B5\nDPV1_Slave = 1\nC1_Read_Write_supp = 0\n"
        'Module = "PPO 3" 0xF1\nEndModule\n'
    )
    text = one_slave_line(
        f"{{name: a, address: 8, gsd: {gsd}, ppo: 3, parameter_access: ds47,"
        " poll: [{parameter: r0021, every: 1s}]}"
    )
    with pytest.raises(ConfigError, match="C1_Read_Write_supp = 0"):
        parse_config(text, environ={})
    texts = one_slave_line(
        "{name: a, address: 8, ident: 0x80B5, ppo: 3, dpv1: true,"
        " poll: [{parameter: r0021, every: 1s}, {parameter: r0020, every: 1s, type: text}]}"
    )
    with pytest.raises(ConfigError, match=r"poll\[1\]: r0020 is a text"):
        parse_config(texts, environ={})
