"""``python -m pkwbus.sim``: options, where it listens, stats as JSON, clean stop."""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import signal
import subprocess
import sys
import time
import urllib.request
from typing import Any

import pytest
import serial

from pkwbus.catalog import DEFAULT_CATALOGS, load_catalog
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.dialects import USS
from pkwbus.sim.cli import configure, main, parse_addresses, parse_host_port, plan
from pkwbus.sim.drives.catalogs import UNIT_FACTORS
from pkwbus.sim.drives.model import TRIPS_PER_HOUR, WARNINGS_PER_HOUR
from pkwbus.sim.drives.table import TABLES
from tests.sim.conftest import request_telegram


def start(*options: str) -> tuple[subprocess.Popen[str], list[str]]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "pkwbus.sim", *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    lines: list[str] = []
    while not lines or not lines[-1].startswith("simulating"):
        line = proc.stdout.readline()
        assert line, f"simulator ended: {proc.stderr.read() if proc.stderr else ''}"
        lines.append(line.strip())
    return proc, lines


def stop(proc: subprocess.Popen[str]) -> tuple[int, float]:
    began = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    code = proc.wait(timeout=5)
    return code, time.monotonic() - began


def test_uss_over_tcp_with_stats(tmp_path: pathlib.Path) -> None:
    stats_file = tmp_path / "stats.json"
    proc, lines = start(
        "--protocol", "uss", "--listen", "tcp://127.0.0.1:0", "--drives", "1,2,3",
        "--stats-listen", "127.0.0.1:0", "--stats-file", str(stats_file),
        "--stats-interval", "50ms", "--dead", "3", "--response-delay", "1ms",
    )  # fmt: skip
    try:
        url = lines[-1].split(" on ")[-1]
        assert url.startswith("socket://127.0.0.1:")
        stats_url = next(line.split()[-1] for line in lines if line.startswith("stats on"))
        with serial.serial_for_url(url, timeout=0.3) as port:
            for address in (1, 2, 3):
                port.write(request_telegram(address, pkw.read(USS, 21), USS))
                answer = port.read(16)
                assert (len(answer), answer[2:3]) == (
                    (16, bytes([address])) if address < 3 else (0, b"")
                )
        with urllib.request.urlopen(stats_url, timeout=2) as response:
            stats = json.load(response)
        assert (stats["requests"], stats["responses"], stats["injected"]["dead"]) == (3, 2, 1)
    finally:
        code, took = stop(proc)
    assert code == 0 and took < 3
    assert json.loads(stats_file.read_text())["responses"] == 2


def test_pty_end_from_the_command_line(tmp_path: pathlib.Path) -> None:
    link = tmp_path / "ttySIM0"
    proc, lines = start("--protocol", "fc", "--pty", str(link), "--drives", "1-2")
    try:
        assert str(link) in lines[-1] and os.path.islink(link)
    finally:
        code, _ = stop(proc)
    assert code == 0 and not link.exists()


@pytest.mark.parametrize(
    "options",
    [
        ["--listen", "tcp://127.0.0.1:0", "--drop", "0.7", "--corrupt", "0.7"],
        ["--listen", "tcp://127.0.0.1:0", "--response-delay", "soon"],
        ["--listen", "127.0.0.1:5020"],
        ["--listen", "tcp://127.0.0.1:0", "--drives", "0"],
        ["--listen", "tcp://127.0.0.1:0", "--wire-timing"],
        ["--listen", "tcp://127.0.0.1:0", "--warnings-per-hour", "-1"],
        ["--listen", "tcp://127.0.0.1:0", "--trips-per-hour", "nan"],
        ["--listen", "tcp://127.0.0.1:0", "--protocol", "uss", "--pkw-words", "5"],
        ["--listen", "tcp://127.0.0.1:0", "--drop-port-per-hour", "-1"],
        ["--listen", "tcp://127.0.0.1:0", "--drop-port-per-hour", "3601"],
        ["--listen", "tcp://127.0.0.1:0", "--drop-port-per-hour", "nan"],
        ["--listen", "tcp://127.0.0.1:0", "--drop-port-per-hour", "1", "--port-outage", "2h"],
        ["--listen", "tcp://127.0.0.1:0", "--port-outage", "soon"],
    ],
)
def test_bad_options_say_one_line_and_exit_2(
    options: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(options) == 2
    err = capsys.readouterr().err
    assert err.startswith("pkwbus simulate: error:") and err.count("\n") == 1


def test_address_and_host_parsing() -> None:
    assert parse_addresses("1,2,5") == [1, 2, 5]
    assert parse_addresses("1-3, 7") == [1, 2, 3, 7]
    assert parse_host_port("tcp://127.0.0.1:5020", "tcp://") == ("127.0.0.1", 5020)
    with pytest.raises(ValueError):
        parse_addresses("a")


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    configure(parser)
    return parser


def read_json(url: str, protocol: str, parameter: str) -> dict[str, Any]:
    done = subprocess.run(
        [sys.executable, "-m", "pkwbus", "read", "--port", url, "--protocol", protocol,
         "--address", "1", parameter, "--json"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    answer: dict[str, Any] = json.loads(done.stdout)
    return answer


def test_without_catalog_the_values_come_in_the_default_catalogs_units() -> None:
    """`pkwbus read` decodes with the protocol's default catalog: the simulator serves with it."""
    proc, lines = start(
        "--protocol", "uss", "--listen", "tcp://127.0.0.1:0", "--drives", "1",
        "--trips-per-hour", "0",  # a tripped drive's frequency is 0
    )  # fmt: skip
    try:
        url = lines[-1].split(" on ")[-1]
        speed = read_json(url, "uss", "r0021")  # the catalog's rpm
        frequency = read_json(url, "uss", "r0024")  # the catalog's Hz
    finally:
        stop(proc)
    assert (speed["unit"], frequency["unit"]) == ("rpm", "Hz")
    assert frequency["value"] > 0
    assert speed["value"] == pytest.approx(frequency["value"] * UNIT_FACTORS["Hz", "rpm"])


@pytest.mark.parametrize("protocol", ["fc", "uss"])
def test_the_catalog_option(protocol: str) -> None:
    def served(*options: str) -> dict[int, str]:
        args = make_parser().parse_args(
            ["--protocol", protocol, "--listen", "tcp://127.0.0.1:0", *options]
        )
        return {pnu: s.unit for pnu, s in plan(args).sim.drives[1].params.specs.items()}

    default = load_catalog(DEFAULT_CATALOGS[protocol])
    units = served()
    assert all(units[pnu] == spec.unit for pnu, spec in default.parameters.items() if spec.unit)
    assert served("--catalog", DEFAULT_CATALOGS[protocol]) == units
    table = {s.pnu: s.unit for s in TABLES[Bus(protocol)]}
    assert served("--catalog", "none") == table


def test_a_pty_path_in_use_is_refused(tmp_path: pathlib.Path) -> None:
    link = tmp_path / "ttySIM0"
    first, _ = start("--protocol", "fc", "--pty", str(link), "--drives", "1")
    try:
        device = os.readlink(link)
        second = subprocess.run(
            [sys.executable, "-m", "pkwbus", "simulate", "--pty", str(link), "--drives", "2"],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert second.returncode == 2
        assert str(link) in second.stderr and second.stderr.count("\n") == 1
        assert os.readlink(link) == device and first.poll() is None
        assert read_json(str(link), "fc", "16-13")["unit"] == "Hz"  # the first one still answers
    finally:
        code, _ = stop(first)
    assert code == 0 and not link.exists()


def test_a_stale_link_of_a_killed_simulator_is_replaced(tmp_path: pathlib.Path) -> None:
    link = tmp_path / "ttySIM0"
    first, _ = start("--protocol", "fc", "--pty", str(link), "--drives", "1")
    # Hold the pty's number while it is stale: another test worker's simulator would
    # otherwise be given it, and the link would point at a pty served (truly in use).
    hold = os.open(os.readlink(link), os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    first.kill()
    first.wait(timeout=10)
    assert os.path.islink(link)  # left behind
    try:
        second, lines = start("--protocol", "fc", "--pty", str(link), "--drives", "1")
    finally:
        os.close(hold)
    try:
        assert lines[-1].endswith(f"{link} -> {os.readlink(link)}")
        assert read_json(str(link), "fc", "16-13")["unit"] == "Hz"
    finally:
        code, _ = stop(second)
    assert code == 0 and not os.path.lexists(link)


@pytest.mark.parametrize("protocol", ["fc", "uss", "profibus"])
def test_refuse_descriptions_reaches_the_drives_named(protocol: str) -> None:
    def described(*options: str) -> dict[int, bool]:
        args = make_parser().parse_args(
            ["--protocol", protocol, "--listen", "tcp://127.0.0.1:0", "--drives", "3-6", *options]
        )
        return {a: d.params.described for a, d in plan(args).sim.drives.items()}

    assert described() == {3: True, 4: True, 5: True, 6: True}
    assert described("--refuse-descriptions", "3,5") == {3: False, 4: True, 5: False, 6: True}
    assert described("--refuse-descriptions", "4-6") == {3: True, 4: False, 5: False, 6: False}


@pytest.mark.parametrize(
    ("refusing", "says"),
    [
        ("x", "'x' is not an address"),
        ("3;5", "'3;5' is not an address"),
        ("200", "address 200 is outside"),
        ("5-3", "runs backwards"),
        ("3,9", "9 is not among --drives 3-5"),
    ],
)
def test_bad_refuse_descriptions(
    refusing: str, says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    options = ["--listen", "tcp://127.0.0.1:0", "--drives", "3-5"]
    assert main([*options, "--refuse-descriptions", refusing]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pkwbus simulate: error: --refuse-descriptions: ")
    assert says in err and err.count("\n") == 1


def describe(
    url: str, protocol: str, address: int, parameter: str
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pkwbus", "describe", "--port", url, "--protocol", protocol,
         "--address", str(address), parameter, "--json"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip


def test_a_drive_served_with_refuse_descriptions_answers_no_description() -> None:
    """Over TCP from ``python -m pkwbus.sim``: `pkwbus describe` of the refusing drive
    fails as a rejection, the other drive describes."""
    proc, lines = start(
        "--protocol", "uss", "--listen", "tcp://127.0.0.1:0", "--drives", "1,2",
        "--refuse-descriptions", "2", "--response-delay", "0",
    )  # fmt: skip
    try:
        url = lines[-1].split(" on ")[-1]
        done = {address: describe(url, "uss", address, "p1120") for address in (1, 2)}
    finally:
        stop(proc)
        for pipe in (proc.stdout, proc.stderr):
            if pipe is not None:
                pipe.close()
    assert done[1].returncode == 0, done[1].stderr
    assert json.loads(done[1].stdout)["unit"] == "s"
    assert done[2].returncode == 1
    assert "describes none of its elements" in done[2].stderr


@pytest.mark.parametrize("protocol", ["fc", "uss", "profibus"])
def test_warning_and_trip_rates_reach_every_drive(protocol: str) -> None:
    def models(*options: str) -> set[tuple[float, float]]:
        args = make_parser().parse_args(
            ["--protocol", protocol, "--listen", "tcp://127.0.0.1:0", "--drives", "3-4", *options]
        )
        drives = plan(args).sim.drives.values()
        return {(d.model.config.warning_rate, d.model.config.trip_rate) for d in drives}

    assert models() == {(WARNINGS_PER_HOUR / 3600, TRIPS_PER_HOUR / 3600)}
    assert models("--warnings-per-hour", "0", "--trips-per-hour", "0") == {(0.0, 0.0)}
    assert models("--warnings-per-hour", "360", "--trips-per-hour", "36") == {(0.1, 0.01)}
