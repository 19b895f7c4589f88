"""`pkwbus gsd FILE`: what pkwbus reads from a GSD file, as text and as JSON; exit 2 with
the line and the reason for a file that is not one."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from pkwbus.cli import main

VENDOR_SHAPED = Path(__file__).parents[1] / "protocol" / "profibus" / "gsd_files" / "mm4_like.gse"


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_json_says_what_the_file_says(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(capsys, "gsd", str(VENDOR_SHAPED), "--json")
    assert code == 0, err
    report = json.loads(out)
    assert (report["vendor"], report["model"], report["ident"]) == (
        "Test Drives GmbH", "TD MICRO 4", "0x80B5",
    )  # fmt: skip
    assert report["dpv1"] == {"read_write": True, "max_data": 240, "response_timeout": 0.01}
    rates = {r["baudrate"]: (r["supported"], r["max_tsdr"]) for r in report["baud_rates"]}
    assert rates[19200] == (True, 15) and rates[12_000_000] == (True, 200)
    assert 31250 not in rates  # neither supported nor given a MaxTsdr
    assert report["user_prm"] == "00 00 00"
    modules = [(m["place"], m["reference"], m["cfg"], m["ppo"]) for m in report["modules"]]
    assert modules[:3] == [(1, 20, "00 E1 D1", None), (2, 21, "F3 F1", 1), (3, 22, "00 F1", 3)]
    assert [m["ppo"] for m in report["modules"] if m["ppo"]] == [1, 3, 2, 4]
    assert report["modules"][1]["bytes"] == {"inputs": 12, "outputs": 12}
    assert report["family"] == {"main": 1, "name": "Drives", "sub": ["Inverter", "Test Drives"]}
    assert report["warnings"] == []


def test_text_shows_modules_and_rates(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "gsd", str(VENDOR_SHAPED))
    assert code == 0
    assert "ident:       0x80B5  DP slave, GSD revision 3" in out
    assert "DP-V1:       yes, data records read and written, at most 240 bytes" in out
    assert "'4 PKW,  2 PZD  (PPO 1)'" in out and "PPO 1" in out
    assert "             1500000     25" in out


def test_what_is_read_past_is_shown(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = tmp_path / "odd.gsd"
    path.write_text('#Profibus_DP\nIdent_Number = 1\nnot a statement\nModule = "A"\nEndModule\n')
    code, out, _ = run(capsys, "gsd", str(path))
    assert code == 0
    assert "read past:   line 3: 'not a statement' read past" in out
    assert "read past:   line 4: module 'A' has no configuration bytes" in out


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("Vendor_Name = 1\n", "not a GSD file: no #Profibus_DP line"),
        ("#Profibus_DP\nIdent_Number = 0xZZ\n", "GSD line 2: ident_number: '0xZZ' is not a number"),
        ('#Profibus_DP\nVendor_Name = "x"\n', "no Ident_Number"),
    ],
)
def test_not_a_gsd_file_exits_2_with_line_and_reason(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "x.gse"
    path.write_text(text)
    code, out, err = run(capsys, "gsd", str(path), "--json")
    assert code == 2 and message in err and "Traceback" not in err
    assert json.loads(out)["error"]["kind"] == "gsd"


def test_a_missing_file_and_a_huge_one(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, _, err = run(capsys, "gsd", str(tmp_path / "nope.gsd"))
    assert code == 2 and "cannot read" in err
    big = tmp_path / "big.gsd"
    big.write_bytes(b"#Profibus_DP\n" + b";" * (1 << 20))
    code, _, err = run(capsys, "gsd", str(big))
    assert code == 2 and "larger than 1 MiB" in err


def test_through_the_real_process() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "pkwbus", "gsd", str(VENDOR_SHAPED), "--json"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["ident"] == "0x80B5"
