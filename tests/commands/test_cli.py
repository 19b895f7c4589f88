"""`pkwbus read`, `write` and `scan` against a simulator in another process."""

from __future__ import annotations

import json
import logging
import re
import subprocess
import sys
from collections.abc import Iterator

import pytest

from pkwbus.catalog import DEFAULT_CATALOGS
from pkwbus.cli import main
from pkwbus.sim import Simulator


def simulate(protocol: str, drives: str) -> Iterator[str]:
    """`pkwbus simulate` in its own process; yields the socket:// URL it prints."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "pkwbus", "simulate", "--protocol", protocol,
         "--listen", "tcp://127.0.0.1:0", "--drives", drives, "--response-delay", "0",
         "--warnings-per-hour", "0", "--trips-per-hour", "0"],  # the status word is checked
        stdout=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    assert proc.stdout is not None
    line = proc.stdout.readline()
    found = re.search(r"socket://127\.0\.0\.1:\d+", line)
    assert found, line
    yield found.group(0)
    proc.terminate()
    assert proc.wait(5) == 0  # Ctrl-C/SIGTERM stop it cleanly


@pytest.fixture(scope="module")
def sim_port() -> Iterator[str]:
    """FC drives at scattered addresses."""
    yield from simulate("fc", "2,17,101")


@pytest.fixture(scope="module")
def uss_port() -> Iterator[str]:
    yield from simulate("uss", "3")


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_read_json(capsys: pytest.CaptureFixture[str], sim_port: str) -> None:
    code, out, err = run(capsys, "read", "--port", sim_port, "--address", "17", "3-41", "--json")
    assert code == 0, err
    body = json.loads(out)
    assert body["parameter"] == "3-41" and body["pnu"] == 341 and body["index"] == 0
    assert body["unit"] == "s"
    assert body["value"] == pytest.approx(body["raw"] / 100)  # conversion index -2


def test_write_then_read(capsys: pytest.CaptureFixture[str], sim_port: str) -> None:
    code, out, err = run(
        capsys, "write", "--port", sim_port, "--address", "2", "3-42", "12.34", "--store", "eeprom"
    )
    assert code == 0, err
    assert "written (eeprom)" in out
    code, out, _ = run(capsys, "read", "--port", sim_port, "--address", "2", "3-42", "--json")
    assert json.loads(out)["raw"] == 1234


def test_rejection_exit_1(capsys: pytest.CaptureFixture[str], sim_port: str) -> None:
    code, out, err = run(capsys, "read", "--port", sim_port, "--address", "2", "999", "--json")
    assert code == 1
    assert err.startswith("fault 0: The parameter number used does not exit")
    assert json.loads(out) == {
        "error": {"kind": "rejected", "fault": 0, "text": "The parameter number used does not exit"}
    }


def test_no_answer_exit_3(capsys: pytest.CaptureFixture[str], sim_port: str) -> None:
    code, _, err = run(
        capsys,
        "read",
        "--port",
        sim_port,
        "--address",
        "5",
        "16-13",
        "--timeout",
        "0.02",
        "--retries",
        "1",
    )
    assert code == 3
    assert "no valid answer" in err


@pytest.mark.parametrize(
    "args",
    [
        ["16-13x"],
        ["5000"],  # beyond FC's 12-bit PNU
        ["16-13", "--type", "u8"],
        ["--protocol", "uss", "70000"],
    ],
)
def test_bad_input_exit_2_and_nothing_sent(
    capsys: pytest.CaptureFixture[str], args: list[str]
) -> None:
    # The port does not even exist: exit 2 proves nothing was opened or sent.
    code, _, err = run(capsys, "read", "--port", "/nonexistent/tty", "--address", "1", *args)
    assert code == 2, err
    assert "Traceback" not in err


def test_bad_write_value_exit_2(capsys: pytest.CaptureFixture[str], sim_port: str) -> None:
    code, _, err = run(
        capsys, "write", "--port", "/nonexistent/tty", "--address", "2", "3-41", "-5"
    )
    assert code == 2
    assert "below the minimum" in err or "range" in err


def test_port_cannot_be_opened_exit_4(
    capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    code, _, err = run(capsys, "read", "--port", "/nonexistent/tty", "--address", "1", "16-13")
    assert code == 4
    assert "cannot open /nonexistent/tty" in err and "Traceback" not in err
    # Said once, by the command: the line's own warning is the service's log, not this.
    assert not [r for r in caplog.records if "/nonexistent/tty" in r.getMessage()]


def test_scan_finds_scattered_addresses(capsys: pytest.CaptureFixture[str], sim_port: str) -> None:
    code, out, err = run(
        capsys, "scan", "--port", sim_port, "--addresses", "1-126", "--timeout", "0.01", "--json"
    )
    assert code == 0, err
    found = json.loads(out)
    assert [d["address"] for d in found] == [2, 17, 101]
    assert all(isinstance(d["status_word"], int) for d in found)
    assert all(d["status"]["running"] for d in found)


def test_uss_float_parameter(capsys: pytest.CaptureFixture[str], uss_port: str) -> None:
    code, out, err = run(
        capsys,
        "write",
        "--port",
        uss_port,
        "--protocol",
        "uss",
        "--address",
        "3",
        "p1082",
        "42.5",
        "--type",
        "f32",
        "--json",
    )
    assert code == 0, err
    code, out, err = run(
        capsys,
        "read",
        "--port",
        uss_port,
        "--protocol",
        "uss",
        "--address",
        "3",
        "p1082",
        "--type",
        "f32",
        "--json",
    )
    assert json.loads(out)["value"] == 42.5


def test_trace_prints_telegrams(capsys: pytest.CaptureFixture[str], sim_port: str) -> None:
    code, _, err = run(capsys, "read", "--port", sim_port, "--address", "2", "16-13", "--trace")
    assert code == 0
    assert re.search(r"tx 02 0e 82 1[0-9a-f] 4d", err)
    assert re.search(r"rx 02 0e 82", err)


def test_describe_reads_the_drives_own_description(
    capsys: pytest.CaptureFixture[str], sim_port: str
) -> None:
    code, out, err = run(
        capsys, "describe", "--port", sim_port, "--address", "17", "3-41", "--json"
    )
    assert code == 0, err
    info = json.loads(out)
    # 3-41 as the simulated drive holds it (served with the default catalog): UInt32, conversion -2.
    held = Simulator("fc", [17], catalog=DEFAULT_CATALOGS["fc"]).drives[17].params.specs[341]
    assert info["data_type"] == {"code": 7, "name": "UInt32"}
    assert info["conversion_index"] == held.conversion == -2
    # Danfoss FC 300 Design Guide, "Read parameter description": element 4's low byte is
    # the unit index, 4 time (seconds at conversion 0); the name a text as long as it is.
    assert (info["unit_index"], info["unit"]) == (4, held.unit) == (4, "s")
    assert info["name"] == held.name
    assert "read_only" not in info  # the FC form does not say
    assert (info["min"], info["max"]) == (held.minimum, held.maximum)


@pytest.mark.parametrize(("parameter", "pnu"), [("r0027", 27), ("p1120", 1120)])
def test_describe_a_uss_drive_in_the_profidrive_form(
    capsys: pytest.CaptureFixture[str], uss_port: str, parameter: str, pnu: int
) -> None:
    """Danfoss VLT PROFIBUS manual MG.33.C4.02, section 5 "Parameter description":
    identifier bit 9 read-only; variable attribute, first byte the size index (22
    current, 4 time), second the conversion index; limits as 32 bits (a float's bits)."""
    code, out, err = run(
        capsys, "describe", "--port", uss_port, "--protocol", "uss", "--address", "3",
        parameter, "--json",
    )  # fmt: skip
    assert code == 0, err
    info = json.loads(out)
    held = Simulator("uss", [3], catalog=DEFAULT_CATALOGS["uss"]).drives[3].params.specs[pnu]
    assert info["data_type"] == {"code": 8, "name": "FloatingPoint32"}
    assert info["conversion_index"] == held.conversion == 0
    assert (info["unit_index"], info["unit"]) == {27: (22, "A"), 1120: (4, "s")}[pnu]
    assert info["unit"] == held.unit
    assert info["read_only"] is (pnu == 27)  # r0027 is a reading, p1120 a setting
    assert info["name"] == held.name[:16].strip()
    if pnu == 1120:
        assert (info["min"], info["max"]) == (held.minimum, held.maximum) == (0.0, 650.0)
    else:
        assert "min" not in info and "max" not in info  # a reading has no limits here
    code, out, _ = run(
        capsys, "describe", "--port", uss_port, "--protocol", "uss", "--address", "3", parameter
    )
    assert code == 0
    assert f"unit: {held.unit}" in out
    assert f"read only: {'yes' if pnu == 27 else 'no'}" in out


def test_describe_needs_a_dialect_with_ak_4(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(
        capsys,
        "describe",
        "--port",
        "/nonexistent",
        "--protocol",
        "uss",
        "--dialect",
        "hitachi-sjpb",
        "--address",
        "1",
        "p1082",
    )
    assert code == 2 and "no description request" in err


def test_a_value_off_the_step_is_refused_not_rounded(
    capsys: pytest.CaptureFixture[str], sim_port: str
) -> None:
    base = ["--port", sim_port, "--address", "101"]
    assert run(capsys, "write", *base, "3-41", "12.34")[0] == 0
    code, out, err = run(capsys, "write", *base, "3-41", "12.345")
    assert code == 2, out
    assert err.strip().endswith("12.345 is not a multiple of 0.01 for 3-41: nearest 12.34 or 12.35")
    code, out, _ = run(capsys, "read", *base, "3-41", "--json")
    assert json.loads(out)["raw"] == 1234  # nothing was written


def test_f32_underflow_is_refused(capsys: pytest.CaptureFixture[str], uss_port: str) -> None:
    base = ["--port", uss_port, "--protocol", "uss", "--address", "3"]
    for value in ("1e-50", "1e-40"):
        code, _, err = run(capsys, "write", *base, "p1120", value)
        assert code == 2
        assert f"{value} is below the smallest f32" in err and "nearest 0 or 1.1754944e-38" in err


def test_one_name_per_drive(capsys: pytest.CaptureFixture[str], sim_port: str) -> None:
    base = ["--port", sim_port, "--address", "17"]
    for written in ("341", "0341", "03-41"):
        code, out, err = run(capsys, "read", *base, written, "--json")
        assert code == 0, err
        assert json.loads(out)["parameter"] == "3-41"
    for written in ("p0341", "r341"):
        code, _, err = run(
            capsys, "write", "--port", "/nonexistent/tty", "--address", "1", written, "1"
        )
        assert code == 2
        assert "Siemens notation" in err and "write 3-41" in err
