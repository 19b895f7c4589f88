"""`pkwbus scan --baudrates`: the commissioning scan against `pkwbus simulate` on a pty.

A pty ignores baud rate and parity, so the simulated drives answer at every
setting: the scan must report each at the first setting it tried (the
fastest rate, the first parity) and not ask again at slower ones.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from pkwbus.commands.scan import AUTO_BAUDRATES

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux ptys")


@pytest.fixture(scope="module")
def pty_sim() -> Iterator[str]:
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "ttySIM")
        proc = subprocess.Popen(
            [sys.executable, "-m", "pkwbus", "simulate", "--protocol", "fc", "--pty", path,
             "--drives", "2,17", "--response-delay", "0",
             "--warnings-per-hour", "0", "--trips-per-hour", "0"],  # the status word is checked
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        assert proc.stdout is not None
        assert path in proc.stdout.readline()
        yield path
        proc.terminate()
        assert proc.wait(5) == 0


def scan(*args: str, stderr: int | None = subprocess.PIPE) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pkwbus", "scan", "--timeout", "20ms", *args],
        stdout=subprocess.PIPE,
        stderr=stderr,
        text=True,
        timeout=120,
    )


def test_each_drive_at_the_first_setting_tried(pty_sim: str) -> None:
    done = scan("--port", pty_sim, "--addresses", "1-3,17", "--baudrates", "9600,19200", "--json")
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout)
    assert [(d["address"], d["baudrate"], d["parity"], d["protocol"]) for d in found] == [
        (2, 19200, "E", "fc"),  # the list is tried fastest first, whatever its order
        (17, 19200, "E", "fc"),
    ]
    assert all(d["type"] == "FC-102" for d in found)  # what the drive says in 15-40
    assert all(d["status"]["running"] for d in found)
    assert done.stderr == ""  # no progress and no summary in --json


def test_auto_starts_at_the_fastest_rate(pty_sim: str) -> None:
    done = scan("--port", pty_sim, "--addresses", "17", "--baudrates", "auto", "--json")
    assert done.returncode == 0, done.stderr
    (drive,) = json.loads(done.stdout)
    assert (drive["baudrate"], drive["parity"]) == (max(AUTO_BAUDRATES), "E")


def test_a_found_drive_and_the_summary(pty_sim: str) -> None:
    done = scan("--port", pty_sim, "--addresses", "2,5", "--baudrates", "19200,9600",
                "--parities", "N,E")  # fmt: skip
    assert done.returncode == 0, done.stderr
    *drives, summary = done.stdout.splitlines()
    assert drives == [
        "address 2: 19200 baud 8N1 fc FC-102, STW 0x0d07 control_ready drive_ready enabled"
        " at_reference frequency_within_limit running"
    ]
    assert summary.startswith("1 drive found: 1 at 19200 baud 8N1 (2 addresses x 4 settings, ")
    assert "\r" not in done.stderr  # stderr is a pipe here: no progress display


def test_parities_without_baudrates_are_tried_at_the_one_rate(pty_sim: str) -> None:
    done = scan("--port", pty_sim, "--addresses", "2", "--parities", "N,E", "--json")
    assert done.returncode == 0, done.stderr
    (drive,) = json.loads(done.stdout)
    assert drive["parity"] == "N"  # the first one tried, at the one rate
    bad = scan("--port", pty_sim, "--addresses", "2", "--parities", "X")
    assert bad.returncode == 2 and "--parities: 'X' is not E, O or N" in bad.stderr


def test_nothing_answered_is_exit_3_with_a_summary(pty_sim: str) -> None:
    done = scan("--port", pty_sim, "--addresses", "5-6", "--baudrates", "19200,9600")
    assert done.returncode == 3
    assert done.stdout == ""
    assert done.stderr.startswith("no drive answered (2 addresses x 6 settings, ")
    plain = scan("--port", pty_sim, "--addresses", "5", "--json")
    assert plain.returncode == 3 and json.loads(plain.stdout) == []


def read_all(fd: int, proc: subprocess.Popen[str]) -> bytes:
    data = b""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            chunk = os.read(fd, 4096)
        except OSError:  # EIO: the child closed its end
            break
        if not chunk:
            break
        data += chunk
    proc.wait(10)
    return data


@pytest.mark.parametrize("json_out", [False, True])
def test_progress_only_on_a_terminal(pty_sim: str, json_out: bool) -> None:
    controller, follower = os.openpty()
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pkwbus", "scan", "--timeout", "20ms", "--port", pty_sim,
             "--addresses", "1-3", "--baudrates", "19200,9600",
             *(["--json"] if json_out else [])],
            stdout=subprocess.PIPE,
            stderr=follower,
            text=True,
        )  # fmt: skip
        os.close(follower)
        follower = -1
        shown = read_all(controller, proc).decode()
    finally:
        with contextlib.suppress(OSError):
            os.close(controller)
        if follower >= 0:
            os.close(follower)
    assert proc.returncode == 0
    if json_out:
        assert shown == ""
    else:
        assert "\r\x1b[K19200 baud 8E1 (1/6): address 1 (1/3), 0 found" in shown
        assert "9600 baud 8N1 (6/6)" in shown
        assert shown.endswith("\r\x1b[K")  # the display is cleared at the end


def test_bad_baudrates_are_exit_2() -> None:
    done = scan("--port", "/nonexistent/tty", "--baudrates", "19200,12345")
    assert done.returncode == 2
    assert "--baudrates: '12345' is not a supported baud rate" in done.stderr
    done = scan("--port", "/nonexistent/tty", "--baudrates", "auto", "--parities", "E,X")
    assert done.returncode == 2 and "--parities: 'X' is not E, O or N" in done.stderr


@contextlib.contextmanager
def uss_sim(pkw_words: str) -> Iterator[str]:
    """`pkwbus simulate --protocol uss` on a pty with the PKW length ``pkw_words``."""
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "ttyUSS")
        proc = subprocess.Popen(
            [sys.executable, "-m", "pkwbus", "simulate", "--protocol", "uss", "--pty", path,
             "--drives", "4", "--response-delay", "0", "--pkw-words", pkw_words],
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        assert proc.stdout is not None
        assert path in proc.stdout.readline()
        try:
            yield path
        finally:
            proc.terminate()
            assert proc.wait(5) == 0


@pytest.mark.parametrize(("sim_words", "shown"), [("variable", "127 (variable)"), ("4", "4")])
def test_a_uss_scan_reports_the_pkw_length(sim_words: str, shown: str) -> None:
    """With its default (auto) the scan asks each USS drive a word read, whose answer's
    length tells the drive's PKW length (the simulator's default is the factory's, 127)."""
    with uss_sim(sim_words) as port:
        done = scan("--port", port, "--protocol", "uss", "--addresses", "3-4", "--json")
        text = scan("--port", port, "--protocol", "uss", "--addresses", "4")
    assert done.returncode == 0, done.stderr
    (drive,) = json.loads(done.stdout)
    assert (drive["address"], drive["pkw_words"]) == (4, shown)
    assert f"PKW length {shown}" in text.stdout.splitlines()[0]
