"""The HTTP address: a port in use is told with the ways to choose another."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from pkwbus.service.assembly.serve import ListenError, bind


def test_an_address_in_use_names_the_options_that_change_it() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        with pytest.raises(ListenError) as info:
            bind("127.0.0.1", port).close()
    message = str(info.value)
    assert f"127.0.0.1:{port}" in message
    assert "--listen" in message and "PKWBUS_LISTEN" in message


def test_a_free_address_is_bound_and_listening() -> None:
    sock = bind("127.0.0.1", 0)
    try:
        with socket.create_connection(sock.getsockname()[:2], timeout=5):
            pass
    finally:
        sock.close()


def test_run_on_an_address_in_use_exits_2_with_one_line(tmp_path: Path) -> None:
    """The composition root tells an unusable address as a configuration problem."""
    config = tmp_path / "pkwbus.yaml"
    config.write_text(
        f"audit_db: {tmp_path / 'audit.sqlite'}\n"
        "lines:\n"
        "  - {name: l1, port: 'socket://127.0.0.1:9', protocol: fc, baudrate: 9600,\n"
        "     drives: [{name: d1, address: 1}]}\n"
    )
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        listen = f"127.0.0.1:{port}"
        done = subprocess.run(
            [sys.executable, "-m", "pkwbus", "run", "--config", str(config), "--listen", listen],
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert done.returncode == 2, done
    assert f"cannot listen on 127.0.0.1:{port}" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr + done.stdout
    assert "internal error" not in done.stderr
