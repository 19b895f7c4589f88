"""A user's mistake on the command line is exit 2 with one clear line, never "internal error".

Each command line of the corpus runs as a real `pkwbus` process with a time
limit, so a mistake that used to hang (``--timeout inf`` waits forever for a
silent drive) fails its case instead of the suite; the address space of the
process is limited too, so one that used to read ``/dev/zero`` to exhaustion
fails fast without starving the machine.
"""

from __future__ import annotations

import os
import re
import resource
import socket
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from pkwbus.commands.common import Exit
from pkwbus.service.audit.log import AuditLog

LIMIT_SECONDS = 30  # generous for a loaded machine; a hang still fails the case
ADDRESS_SPACE = 2 << 30  # bytes: far more than pkwbus needs, far less than the machine has


@dataclass(frozen=True)
class Places:
    """What the command lines of the corpus refer to."""

    silent: str  # socket:// URL of a TCP port that accepts and never answers
    tty: str  # a pseudo-terminal: a real serial device to pyserial
    config: str  # a valid configuration whose audit database exists
    slow_config: str  # a configuration with an absurd telegram timeout
    gateway_config: str  # a configuration whose gateway's TCP port does not exist
    big: str  # a 2 MiB file


@pytest.fixture(scope="module")
def places(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Places]:
    tmp = tmp_path_factory.mktemp("mistakes")
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(8)  # connections complete in the backlog; nothing is ever read or sent
    controller, device = os.openpty()
    audit = tmp / "audit.sqlite"
    AuditLog(audit).close()
    config = tmp / "ok.yaml"
    config.write_text(_config(audit, "100ms"))
    slow = tmp / "slow.yaml"
    slow.write_text(_config(audit, '"999999999999h"'))
    gateway = tmp / "gateway.yaml"
    gateway.write_text(_config(audit, "100ms", "socket://127.0.0.1:99999"))
    big = tmp / "big.yaml"
    big.write_text("# padding\n" * (200 * 1024 + 1))
    try:
        yield Places(
            silent=f"socket://127.0.0.1:{silent.getsockname()[1]}",
            tty=os.ttyname(device),
            config=str(config),
            slow_config=str(slow),
            gateway_config=str(gateway),
            big=str(big),
        )
    finally:
        silent.close()
        os.close(controller)
        os.close(device)


def _config(audit: Path, timeout: str, port: str = "sim://fc?drives=1") -> str:
    return textwrap.dedent(
        f"""\
        audit_db: {audit}
        lines:
          - name: l1
            port: {port}
            protocol: fc
            baudrate: 19200
            timeout: {timeout}
            drives:
              - name: d1
                address: 1
                poll: [{{parameter: "16-13", every: 1s}}]
        """
    )


# Each mistake: the command line ({silent}, {tty}, ... name Places' fields) and what the
# message must say.
MISTAKES: dict[str, tuple[str, str]] = {
    "audit limit overflows SQLite": (
        "audit --config {config} --limit 99999999999999999999999",
        "--limit: 99999999999999999999999 is outside 1-10000",
    ),
    "audit limit zero": ("audit --config {config} --limit 0", "--limit: 0 is outside 1-10000"),
    "audit limit text": ("audit --config {config} --limit many", "'many' is not a whole number"),
    "baud rate overflows termios": (
        "read --port {tty} --baudrate 99999999999 --address 1 16-13",
        "'99999999999' is not a supported baud rate",
    ),
    "baud rate not standard": (
        "read --port {tty} --baudrate 12345 --address 1 16-13",
        "'12345' is not a supported baud rate",
    ),
    "timeout inf hangs": (
        "read --port {silent} --address 1 16-13 --timeout inf",
        "--timeout: 'inf' is not a duration",
    ),
    "timeout 1e308 hangs": (
        "read --port {silent} --address 1 16-13 --timeout 1e308",
        "--timeout: '1e308' is not a duration",
    ),
    "timeout nan": (
        "read --port {silent} --address 1 16-13 --timeout nan",
        "--timeout: 'nan' is not a duration",
    ),
    "timeout hours": (
        "scan --port {silent} --timeout 999999999999h",
        "'999999999999h' is too long for a telegram timeout (1 ms to 10 s)",
    ),
    "timeout negative": (
        "describe --port {silent} --address 1 16-13 --timeout -1",
        "'-1' is not a duration above 0",
    ),
    "deadline negative": (
        "read --port {silent} --address 1 16-13 --deadline -1",
        "--deadline: '-1' is not a duration above 0: a job deadline is 1 ms to 1 h",
    ),
    "deadline nan": (
        "write --port {silent} --address 1 3-41 5 --deadline nan",
        "--deadline: 'nan' is not a duration",
    ),
    "deadline too long": (
        "read --port {silent} --address 1 16-13 --deadline 2h",
        "'2h' is too long for a job deadline (1 ms to 1 h)",
    ),
    "retries huge": (
        "read --port {silent} --address 1 16-13 --retries 99999999999",
        "--retries: 99999999999 is outside 0-100",
    ),
    "retries negative": (
        "read --port {silent} --address 1 16-13 --retries -1",
        "--retries: -1 is outside 0-100",
    ),
    "address huge": (
        "read --port {silent} --address 99999999999999999999 16-13",
        "address 99999999999999999999 is outside 1-126",
    ),
    "scan addresses exhaust memory": (
        "scan --port {silent} --addresses 1-99999999999999",
        "--addresses: address 99999999999999 is outside 1-126",
    ),
    "gateway port out of range": (
        "read --port socket://127.0.0.1:99999 --address 1 16-13",
        "the TCP port must be 1-65535",
    ),
    "simulate listen port overflows bind": (
        "simulate --listen tcp://127.0.0.1:99999",
        "'tcp://127.0.0.1:99999': the TCP port must be 0-65535 (0: any free port)",
    ),
    "simulate stats port overflows bind": (
        "simulate --listen tcp://127.0.0.1:0 --stats-listen 127.0.0.1:99999",
        "'127.0.0.1:99999': the TCP port must be 0-65535 (0: any free port)",
    ),
    "simulate drives exhaust memory": (
        "simulate --listen tcp://127.0.0.1:0 --drives 1-99999999999",
        "address 99999999999 is outside 0-126",
    ),
    "simulate lag in telegrams": (
        "simulate --listen tcp://127.0.0.1:0 --lag 99999999999999999999999",
        "--lag: 99999999999999999999999 is outside 0-1000",
    ),
    "simulate lag duration": (
        "simulate --listen tcp://127.0.0.1:0 --lag 999999999999h",
        "--lag: '999999999999h' is too long for a simulated PKW lag (0 to 1 h)",
    ),
    "simulate response delay": (
        "simulate --listen tcp://127.0.0.1:0 --response-delay 1h",
        "--response-delay: '1h' is too long for a response delay (0 to 10 s)",
    ),
    "simulate stats interval zero": (
        "simulate --listen tcp://127.0.0.1:0 --stats-interval 0",
        "--stats-interval: '0' is not a duration above 0",
    ),
    "simulate late answers": (
        "simulate --listen tcp://127.0.0.1:0 --late-after=-5s",
        "--late-after: '-5s' is not a duration 0 or more",
    ),
    "simulate baud rate": (
        "simulate --listen tcp://127.0.0.1:0 --wire-timing --baudrate 99999999999999999999",
        "--baudrate: 99999999999999999999 is not a supported baud rate",
    ),
    "simulate pkw words": (
        "simulate --listen tcp://127.0.0.1:0 --pkw-words many",
        "--pkw-words: 'many' is not a PKW length",
    ),
    "check-config reads /dev/zero": (
        "check-config /dev/zero",
        "/dev/zero: larger than 1 MiB",
    ),
    "check-config of a big file": ("check-config {big}", "larger than 1 MiB"),
    "check-config with an absurd timeout": (
        "check-config {slow_config}",
        "lines[0].timeout: '999999999999h' is too long for a telegram timeout (1 ms to 10 s)",
    ),
    "check-config with a gateway's port out of range": (
        "check-config {gateway_config}",
        "lines[0].port: 'socket://127.0.0.1:99999': the TCP port must be 1-65535",
    ),
    "run with an absurd timeout": (
        "run --config {slow_config} --listen 127.0.0.1:1",
        "lines[0].timeout: '999999999999h' is too long",
    ),
}


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


@pytest.mark.parametrize("name", sorted(MISTAKES))
def test_a_mistake_exits_2_with_one_clear_line(name: str, places: Places) -> None:
    line, message = MISTAKES[name]
    argv = line.format(**vars(places)).split()
    try:
        done = subprocess.run(
            [sys.executable, "-m", "pkwbus", *argv],
            capture_output=True,
            text=True,
            timeout=LIMIT_SECONDS,
            stdin=subprocess.DEVNULL,
            preexec_fn=_limit_memory,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"{line}: still running after {LIMIT_SECONDS} s")
    err = done.stderr
    assert done.returncode == 2, (line, done.returncode, err)
    assert message in err, err
    assert "Traceback" not in err + done.stdout and "internal error" not in err, err
    assert done.stdout == ""
    if argv[0] not in ("check-config", "run"):  # those list the configuration's problems
        assert err.count("\n") == 1, err


def test_the_readme_lists_every_exit_code() -> None:
    readme = Path(__file__).resolve().parents[2] / "README.md"
    listed = re.findall(r"^\| (\d+) \| .+ \|$", readme.read_text(encoding="utf-8"), re.M)
    assert sorted(int(code) for code in listed) == sorted(Exit)
