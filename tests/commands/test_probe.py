"""`pkwbus check-config --probe`: each configured drive asked once with the line's settings."""

from __future__ import annotations

import contextlib
import re
import socket
import socketserver
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest


@contextlib.contextmanager
def simulated(path: Path, protocol: str, *options: str) -> Iterator[str]:
    """`pkwbus simulate` with drives 1 and 2 on a pty at ``path``."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "pkwbus", "simulate", "--protocol", protocol, "--pty", str(path),
         "--drives", "1,2", "--response-delay", "1ms", *options],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        assert "simulating" in proc.stdout.readline()
        yield str(path)
    finally:
        proc.terminate()
        proc.wait(10)


@pytest.fixture
def pty(tmp_path: Path) -> Iterator[str]:
    with simulated(tmp_path / "ttySIM", "fc") as path:
        yield path


def config(tmp_path: Path, port: str, addresses: list[int]) -> Path:
    drives = "".join(
        f"\n      - {{name: d{a}, address: {a}, catalog: danfoss-fc}}" for a in addresses
    )
    path = tmp_path / "config.yaml"
    path.write_text(
        f"audit_db: {tmp_path / 'audit.sqlite'}\n"
        f"lines:\n  - name: hall\n    port: {port}\n    protocol: fc\n    baudrate: 19200\n"
        f"    timeout: 50ms\n    retries: 1\n    drives:{drives}\n"
        f"  - name: demo\n    port: sim://fc?drives=5\n    protocol: fc\n    baudrate: 19200\n"
        f"    drives:\n      - {{name: s5, address: 5}}\n"
    )
    return path


def check(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pkwbus", "check-config", "--probe", str(path)],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip


def test_every_drive_answers(pty: str, tmp_path: Path) -> None:
    done = check(config(tmp_path, pty, [1, 2]))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "d1 (address 1): answers" in done.stdout
    assert "d2 (address 2): answers" in done.stdout
    assert "line demo: simulated" in done.stdout and "not probed" in done.stdout


def test_a_drive_that_does_not_answer_is_named_and_exits_3(pty: str, tmp_path: Path) -> None:
    done = check(config(tmp_path, pty, [1, 7]))
    assert done.returncode == 3, done.stdout + done.stderr
    assert "d1 (address 1): answers" in done.stdout
    assert "d7 (address 7): NO ANSWER" in done.stdout
    assert "Traceback" not in done.stderr


def test_a_port_that_cannot_be_opened_is_said_once_and_exits_4(tmp_path: Path) -> None:
    port = str(tmp_path / "no-such-tty")
    done = check(config(tmp_path, port, [1]))
    assert done.returncode == 4, done  # the exit code of a port that cannot be opened
    assert f"line hall: cannot open {port}" in done.stdout
    assert done.stdout.count(port) == 1 and done.stdout.count("cannot open") == 1
    assert "WARNING" not in done.stderr, done.stderr  # the command says it, not the log


@pytest.fixture
def echoing_adapter() -> Iterator[str]:
    """`pkwbus simulate` on TCP behind a relay that, as an RS-485 adapter hearing its own
    transmission does, sends every request back before the drive's answer."""
    sim = subprocess.Popen(
        [sys.executable, "-m", "pkwbus", "simulate", "--protocol", "fc", "--listen",
         "tcp://127.0.0.1:0", "--drives", "1", "--response-delay", "0"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert sim.stdout is not None
    found = re.search(r"socket://127\.0\.0\.1:(\d+)", sim.stdout.readline())
    assert found
    sim_port = int(found[1])

    def telegram(sock: socket.socket) -> bytes:
        """One whole FC telegram (STX, LGE, then LGE bytes), however TCP splits it."""
        data = b""
        while len(data) < 2 or len(data) < data[1] + 2:
            chunk = sock.recv(256)
            if not chunk:
                return b""
            data += chunk
        return data

    class Relay(socketserver.BaseRequestHandler):
        def handle(self) -> None:
            with socket.create_connection(("127.0.0.1", sim_port)) as drive:
                drive.settimeout(5)
                while request := telegram(self.request):
                    self.request.sendall(request)  # the echo
                    drive.sendall(request)
                    self.request.sendall(telegram(drive))

    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Relay)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        yield f"socket://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        sim.terminate()
        sim.wait(10)


def test_an_echoing_adapter_is_named(echoing_adapter: str, tmp_path: Path) -> None:
    done = check(config(tmp_path, echoing_adapter, [1]))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "d1 (address 1): answers" in done.stdout  # the echo is not taken for the answer
    assert f"the adapter on {echoing_adapter} echoes our requests: set echo: true" in done.stdout


def test_no_echo_warning_without_an_echo(pty: str, tmp_path: Path) -> None:
    done = check(config(tmp_path, pty, [1]))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "echoes our requests" not in done.stdout


def test_a_uss_drive_is_reported_with_its_pkw_length(tmp_path: Path) -> None:
    """A factory-set drive (127) answers: auto shows 127, and pkw_words: 4 is a conflict."""
    with simulated(tmp_path / "ttyUSS", "uss") as path:
        conf = tmp_path / "uss.yaml"
        conf.write_text(
            f"audit_db: {tmp_path / 'audit.sqlite'}\n"
            f"lines:\n  - name: hall\n    port: {path}\n    protocol: uss\n"
            f"    baudrate: 19200\n    timeout: 50ms\n    retries: 1\n    drives:\n"
            f"      - {{name: d1, address: 1}}\n"
            f"      - {{name: d2, address: 2, pkw_words: 4}}\n"
        )
        done = check(conf)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "d1 (address 1): answers, PKW length 127 (variable) (pkw_words: auto)" in done.stdout
    assert "d2 (address 2): answers, PKW length 127 (variable), but pkw_words is 4" in done.stdout
    assert "CONFLICT" in done.stdout


def test_each_parameter_as_the_drive_describes_it_against_the_catalog(tmp_path: Path) -> None:
    """Simulated without the catalog, the FC drive keeps its own 1-20 in hundredths of a kW
    where the catalog says conversion index 1 (W): the probe names the difference; 16-14
    agrees; a drive with describe: off is not asked."""
    with simulated(tmp_path / "ttyFC", "fc", "--catalog", "none") as path:
        conf = tmp_path / "fc.yaml"
        conf.write_text(
            f"audit_db: {tmp_path / 'audit.sqlite'}\n"
            f"lines:\n  - name: hall\n    port: {path}\n    protocol: fc\n"
            f"    baudrate: 19200\n    timeout: 50ms\n    retries: 1\n    drives:\n"
            f"      - {{name: d1, address: 1, catalog: danfoss-fc,"
            f' poll: [{{parameter: "16-14", every: 1s}}], writable: ["1-20"]}}\n'
            f"      - {{name: d2, address: 2, catalog: danfoss-fc, describe: off,"
            f' poll: [{{parameter: "16-14", every: 1s}}]}}\n'
        )
        done = check(conf)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    (current,) = [line for line in lines if line.strip().startswith("16-14:")]
    assert "Int32" in current and "x0.01" in current and "the catalog agrees" in current
    (power,) = [line for line in lines if line.strip().startswith("1-20:")]
    assert "CATALOG DIFFERS" in power
    assert "scaling: drive x0.01, catalog x10" in power
    assert sum(line.strip().startswith("16-14:") for line in lines) == 1  # d2 not described
