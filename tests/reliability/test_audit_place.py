"""An ``audit_db`` or ``history_db`` that cannot be a database here: `check-config` and
`run` name it and exit 2 (a configuration problem), never 70 (an internal error), without
a traceback; `pkwbus audit` too."""

from __future__ import annotations

import socket
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from pkwbus import cli

from .helpers import tmpfs

LINES = (
    "lines:\n"
    "  - {name: l1, port: 'socket://127.0.0.1:9', protocol: fc, baudrate: 9600,\n"
    "     drives: [{name: d1, address: 1}]}\n"
)


def directory(tmp: Path) -> Path:
    (tmp / "adir").mkdir()
    return tmp / "adir"


def under_a_file(tmp: Path) -> Path:
    (tmp / "plain").write_text("")
    return tmp / "plain" / "var" / "audit.sqlite"


def device(tmp: Path) -> Path:
    return Path("/dev/null")


PLACES: dict[str, tuple[Callable[[Path], Path], str]] = {
    "directory": (directory, "is a directory"),
    "dev_null": (device, "not a regular file"),
    "parent_is_a_file": (under_a_file, "cannot be created"),
}


@pytest.fixture(params=[*PLACES, "read_only_fs"])
def bad_place(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[Path, str]]:
    if request.param == "read_only_fs":
        with tmpfs(tmp_path / "ro", "64k", readonly=True) as ro:
            yield ro / "audit.sqlite", "not writable"
        return
    make, says = PLACES[request.param]
    yield make(tmp_path), says


def config(tmp: Path, audit_db: Path, key: str = "audit_db") -> Path:
    path = tmp / "pkwbus.yaml"
    if key == "audit_db":
        path.write_text(f"audit_db: {audit_db}\n{LINES}")
    else:  # the audit log in a good place, the other database in the bad one
        path.write_text(f"audit_db: {tmp / 'audit.sqlite'}\n{key}: {audit_db}\n{LINES}")
    return path


@pytest.mark.parametrize("key", ["audit_db", "history_db"])
def test_check_config_and_run_refuse_the_place(
    bad_place: tuple[Path, str], tmp_path: Path, capsys: pytest.CaptureFixture[str], key: str
) -> None:
    place, says = bad_place
    path = config(tmp_path, place, key)
    assert cli.main(["check-config", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{key}:" in err and says in err, err
    # The service stops at its audit_db before it binds: an address this test holds is
    # one no other test worker can take meanwhile, and were it bound, a refusal too.
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen(1)
        listen = f"127.0.0.1:{held.getsockname()[1]}"
        done = subprocess.run(
            [sys.executable, "-m", "pkwbus", "run", "--config", str(path), "--listen", listen],
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert done.returncode == 2, done
    assert f"{key}:" in done.stderr and says in done.stderr, done.stderr
    assert "Traceback" not in done.stderr + done.stdout
    assert "internal error" not in done.stderr
    assert not Path("/dev/null-journal").exists() and not Path("/dev/null-wal").exists()


@pytest.mark.parametrize("make", [directory, device], ids=["directory", "dev_null"])
def test_audit_command_refuses_what_is_not_a_database(
    make: Callable[[Path], Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = config(tmp_path, make(tmp_path))
    assert cli.main(["audit", "--config", str(path)]) == 2
    assert "not an audit database" in capsys.readouterr().err


def test_audit_command_on_a_damaged_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "audit.sqlite"
    db.write_bytes(b"this is no database" * 100)
    assert cli.main(["audit", "--config", str(config(tmp_path, db))]) == 2
    err = capsys.readouterr().err
    assert "cannot read the audit log" in err or "cannot open the audit log" in err
