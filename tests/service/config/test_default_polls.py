"""The counters a drive keeps of its own life, polled by default where its catalog marks
them (``counters: auto``): each element of an array, never one the configuration polls,
and one that no vendor document types only where the drive is asked to describe it."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from pkwbus.catalog import load_catalog
from pkwbus.service.config import default_polls, load_config
from pkwbus.service.config.default_polls import COUNTER_EVERY, counter_polls
from pkwbus.service.config.line_load import check_config_report, line_load
from tests.service.config.test_config import parse


def config(catalog: str, protocol: str, drive_extra: str = "", polls: str = "[]") -> str:
    return f"""
lines:
  - name: l1
    port: /dev/ttyS1
    protocol: {protocol}
    baudrate: 19200
    drives:
      - name: d
        address: 1
        catalog: {catalog}
        alarms: off
        poll: {polls}
{drive_extra}"""


def counters(text: str) -> list[tuple[str, bool]]:
    cfg = parse(text)
    line = cfg.lines[0]
    drive = line.drives[0]
    return [(str(ref), typed) for ref, typed in counter_polls(line, drive)]


def marked(catalog: str) -> list[tuple[int, int | None]]:
    """What the catalog file marks as counters, each element of an array."""
    found: list[tuple[int, int | None]] = []
    for spec in load_catalog(catalog).parameters.values():
        if spec.counter:
            found += (
                [(spec.pnu, i) for i in range(spec.array)] if spec.array else [(spec.pnu, None)]
            )
    return found


@pytest.mark.parametrize(("catalog", "protocol"), [("danfoss-fc", "fc"), ("siemens-g120", "uss")])
def test_every_counter_the_catalog_marks_is_polled_by_default(catalog: str, protocol: str) -> None:
    found = counters(config(catalog, protocol))
    expected = [(f"{pnu}" if i is None else f"{pnu}[{i}]") for pnu, i in marked(catalog)]
    assert [name for name, _ in found] == expected
    assert expected, "the catalog marks the drive's counters"


def test_the_danfoss_counters_are_operating_and_running_hours_energy_and_events() -> None:
    assert {pnu for pnu, _ in marked("danfoss-fc")} == {1500, 1501, 1502, 1503, 1504, 1505}
    assert {pnu for pnu, _ in marked("siemens-g120")} == {39, 2114}


def test_a_counter_the_configuration_polls_is_not_polled_twice() -> None:
    fc_polls = '[{parameter: "15-03", every: 5s}]'
    fc = [name for name, _ in counters(config("danfoss-fc", "fc", polls=fc_polls))]
    assert "1503" not in fc and "1500" in fc
    uss_polls = "[{parameter: r0039, index: 1, every: 5s}]"
    uss = [name for name, _ in counters(config("siemens-g120", "uss", polls=uss_polls))]
    assert "39[1]" not in uss and "39[0]" in uss and "39[2]" in uss


def test_counters_off_polls_none() -> None:
    assert counters(config("danfoss-fc", "fc", "        counters: off")) == []


def test_a_counter_no_document_types_needs_the_drives_own_description(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    found = counters(config("danfoss-fc", "fc"))
    assert found and not any(typed for _, typed in found), "their types are recalled"
    assert counters(config("danfoss-fc", "fc", "        describe: off")) == []
    # Where a document types one (the catalog's verified), it is polled without.
    shipped = default_polls.load_catalog("danfoss-fc")
    typed = shipped.parameters[1503].model_copy(update={"verified": True})
    sourced = shipped.model_copy(update={"parameters": {**shipped.parameters, 1503: typed}})
    monkeypatch.setattr(default_polls, "load_catalog", lambda name: sourced)
    assert counters(config("danfoss-fc", "fc", "        describe: off")) == [("1503", True)]


def test_the_counters_polled_by_default_count_in_the_estimate() -> None:
    on = parse(config("danfoss-fc", "fc"))
    off = parse(config("danfoss-fc", "fc", "        counters: off"))
    added = (
        line_load(on.lines[0]).exchanges_per_second - line_load(off.lines[0]).exchanges_per_second
    )
    assert added == pytest.approx(len(marked("danfoss-fc")) / COUNTER_EVERY)


def test_check_config_tells_the_counters_share_of_the_line() -> None:
    from pkwbus.service.config.line_load import check_config_report

    on = parse(config("danfoss-fc", "fc"))
    off = parse(config("danfoss-fc", "fc", "        counters: off"))
    (told,) = [r for r in check_config_report(on) if "polled by default (counters)" in r]
    assert told.lstrip().startswith(f"{len(marked('danfoss-fc'))} counter(s) of 1 drive(s)")
    share = line_load(on.lines[0]).utilisation - line_load(off.lines[0]).utilisation
    assert f"{share:.2%} of the line's time" in told
    assert not [r for r in check_config_report(off) if "(counters)" in r]


# ------------------------------------------------------------ the settings sweep


def swept(text: str) -> tuple[float, list[str]]:
    cfg = parse(text)
    line = cfg.lines[0]
    every, refs = default_polls.swept_settings(line, line.drives[0])
    return every, [str(ref) for ref in refs]


@pytest.mark.parametrize(("catalog", "protocol"), [("danfoss-fc", "fc"), ("siemens-g120", "uss")])
def test_the_sweep_reads_every_setting_the_catalog_marks_each_hour(
    catalog: str, protocol: str
) -> None:
    every, found = swept(config(catalog, protocol))
    specs = load_catalog(catalog).parameters.values()
    expected = [str(s.pnu) for s in specs if s.setting or (s.setting is None and s.writable)
                or (s.setting is None and s.prefix == "p")]  # fmt: skip
    assert every == 3600.0 and found == expected and found


def test_the_danfoss_settings_are_its_motor_data_limits_ramps_and_bus_timing() -> None:
    _, found = swept(config("danfoss-fc", "fc"))
    assert set(found) == {
        "1", "120", "122", "123", "124", "302", "303", "341", "342", "412", "414", "835",
        "836", "837",
    }  # fmt: skip


@pytest.mark.parametrize(
    ("extra", "every", "found"),
    [
        ("        settings: off", 0.0, []),
        ('        settings: {every: 10m, parameters: ["3-41", "1-20"]}', 600.0, ["3-41", "1-20"]),
    ],
)
def test_a_drive_may_turn_the_sweep_off_or_list_what_it_reads(
    extra: str, every: float, found: list[str]
) -> None:
    assert swept(config("danfoss-fc", "fc", extra)) == (every, found)


@pytest.mark.parametrize(
    ("extra", "problem"),
    [
        ("        settings: {every: 25h}", "settings.every"),
        ("        settings: {every: 10m, parameters: everything}", "settings.parameters"),
        ("        settings: sometimes", "settings"),
        ('        settings: {parameters: ["p1120"]}', "settings.parameters[0]"),
    ],
)
def test_a_bad_sweep_is_a_configuration_problem_naming_its_place(extra: str, problem: str) -> None:
    with pytest.raises(Exception, match=rf"drives\[0\]\.{re.escape(problem)}"):
        parse(config("danfoss-fc", "fc", extra))


def test_check_config_counts_the_sweep_after_the_polls() -> None:
    cfg = parse(config("danfoss-fc", "fc", "        settings: {every: 1m}"))
    load = line_load(cfg.lines[0])
    exchange = load.exchange_seconds["d"]
    assert load.sweeping == pytest.approx(14 * exchange / 60)
    off = line_load(parse(config("danfoss-fc", "fc", "        settings: off")).lines[0])
    assert off.sweeping == 0.0 and off.utilisation == load.utilisation


def test_check_config_counts_the_sweep_on_a_profibus_line_per_slave() -> None:
    config = load_config(Path(__file__).parents[3] / "config" / "demo.yaml")
    (line,) = [line for line in config.lines if line.name == "dp_line"]
    swept = [d for d in line.drives if default_polls.swept_settings(line, d)[1]]
    count = sum(len(default_polls.swept_settings(line, d)[1]) for d in swept)
    said = f"  {count} setting(s) of {len(swept)} slave(s) swept (settings): at most"
    assert swept and any(row.startswith(said) for row in check_config_report(config))
