"""A real mosquitto for the MQTT tests: started on a free loopback port in a temp dir, with a
password file (``mosquitto_passwd -b``) and an ACL, killed at the end; the tests skip with a
reason when the broker is not installed.

Accounts: ``pkwbus`` (the service: everything under ``pkwbus/`` and ``spBv1.0/``, the
replies), ``op1`` (may publish sets as op1 only, reads ``pkwbus/#`` and its replies),
``op2`` (may publish sets as op2 only: a set it publishes under op1's name is dropped by
the broker).
"""

from __future__ import annotations

import contextlib
import getpass
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

MOSQUITTO = shutil.which("mosquitto") or (
    "/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").exists() else None
)
MOSQUITTO_PASSWD = shutil.which("mosquitto_passwd")

USERS = {"pkwbus": "service-pw-1", "op1": "op1-pw-2", "op2": "op2-pw-3", "scada": "scada-pw-4"}

ACL = """\
user pkwbus
topic readwrite pkwbus/#
topic readwrite spBv1.0/#
topic write replies/#

user scada
topic readwrite spBv1.0/#

pattern write pkwbus/+/+/set/%u/#
pattern read replies/%u/#
pattern read pkwbus/#
"""


@dataclass(frozen=True)
class Broker:
    host: str
    port: int
    directory: Path

    def log(self) -> str:
        path = self.directory / "mosquitto.log"
        return path.read_text(errors="replace") if path.exists() else ""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def mosquitto(directory: Path, acl: str = ACL) -> Iterator[Broker]:
    """A mosquitto with :data:`USERS` and ``acl``, listening on 127.0.0.1."""
    if MOSQUITTO is None or MOSQUITTO_PASSWD is None:
        pytest.skip("mosquitto is not installed (Debian: apt-get install mosquitto)")
    directory.mkdir(parents=True, exist_ok=True)
    passwords = directory / "passwords"
    for user, password in USERS.items():
        create = ["-c"] if not passwords.exists() else []
        subprocess.run(
            [MOSQUITTO_PASSWD, *create, "-b", str(passwords), user, password],
            check=True,
            capture_output=True,
        )
    (directory / "acl").write_text(acl)
    port = _free_port()
    conf = directory / "mosquitto.conf"
    conf.write_text(
        f"listener {port} 127.0.0.1\n"
        "allow_anonymous false\n"
        f"password_file {passwords}\n"
        f"acl_file {directory / 'acl'}\n"
        "persistence false\n"
        # Started as root (a CI container), mosquitto would become "mosquitto" and lose
        # the temp dir: it stays the user that started it.
        f"user {getpass.getuser()}\n"
        f"log_dest file {directory / 'mosquitto.log'}\n"
        "log_type all\n"
    )
    output = (directory / "mosquitto.out").open("wb")
    process = subprocess.Popen([MOSQUITTO, "-c", str(conf)], stdout=output, stderr=output)
    try:
        end = time.monotonic() + 20.0
        while True:
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.5):
                break
            if process.poll() is not None or time.monotonic() > end:
                said = (directory / "mosquitto.out").read_text(errors="replace")
                raise AssertionError(f"mosquitto did not start: {said}")
            time.sleep(0.05)
        yield Broker("127.0.0.1", port, directory)
    finally:
        process.kill()
        process.wait()
        output.close()
