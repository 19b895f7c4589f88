"""``python -m pkwbus.sim``: options, where it listens, stats as JSON, clean stop."""

from __future__ import annotations

import json
import os
import pathlib
import signal
import subprocess
import sys
import time
import urllib.request

import pytest
import serial

from pkwbus.protocol import pkw
from pkwbus.protocol.dialects import USS
from pkwbus.sim.cli import main, parse_addresses, parse_host_port
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
        ["--listen", "tcp://127.0.0.1:0", "--protocol", "uss", "--pkw-words", "5"],
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
