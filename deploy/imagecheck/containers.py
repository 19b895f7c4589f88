"""Starting the containers and the simulated serial line, and waiting for them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from .processes import free_port, http, logs, on_exit, podman, rm_container, rm_volume, wait_until
from .report import CheckFailed, say
from .settings import DEMO, HARDENED, HEALTH_LIMIT_S, IMAGE, PREFIX

# --- the image's demo configuration ----------------------------------------------------


def start_demo() -> tuple[str, str, int]:
    """The image's own demo configuration, hardened as docs/deploy.md says, waited for until
    /healthz and /readyz answer 200: its container, its volume and its port on 127.0.0.1."""
    name, volume, port = f"{PREFIX}-demo", f"{PREFIX}-demo-data", free_port()
    on_exit(lambda: rm_volume(volume))
    on_exit(lambda: rm_container(name))
    podman(
        "run",
        "-d",
        "--name",
        name,
        *HARDENED,
        "-v",
        f"{volume}:/var/lib/pkwbus",
        "-p",
        f"127.0.0.1:{port}:9725",
        "-e",
        "PKWBUS_WRITE_TOKEN",
        IMAGE,
        "run",
        "--config",
        "/usr/share/pkwbus/demo.yaml",
        "--listen",
        "0.0.0.0:9725",
    )
    started = time.monotonic()
    try:
        wait_until(
            "/healthz", lambda: http(f"http://127.0.0.1:{port}/healthz")[0] == 200, HEALTH_LIMIT_S
        )
        healthy = time.monotonic() - started
        wait_until(
            "/readyz 200", lambda: http(f"http://127.0.0.1:{port}/readyz")[0] == 200, HEALTH_LIMIT_S
        )
        ready = time.monotonic() - started
        say(f"    /healthz after {healthy:.1f}s, /readyz 200 after {ready:.1f}s")
    except CheckFailed as exc:
        raise CheckFailed(f"{exc}\n{logs(name)}") from None
    return name, volume, port


# --- a simulated serial line on a pty ---------------------------------------------------

SERIAL_LINE = """
  - name: serial_line
    port: /dev/ttyUSB0
    protocol: fc
    baudrate: 19200
    parity: E
    timeout: 100ms
    retries: 1
    settings: {every: 10s}  # a complete sweep soon: the dashboard's sweep age has data
    drives:
""" + "".join(
    f"""      - name: {name}
        address: {address}
        catalog: danfoss-fc
        poll:
          - {{parameter: "16-13", every: 1s}}
          - {{parameter: "16-14", every: 1s}}
          - {{parameter: "16-03", every: 2s}}
          - {{parameter: "16-90", every: 5s}}
        writable: ["3-41"]
"""
    for name, address in (("press_1", 1), ("press_2", 2), ("dead_press", 3))
)


def line_config() -> str:
    """The demo's two lines plus a line on /dev/ttyUSB0 (the pty passed in with --device)."""
    demo = DEMO.read_text()
    demo = demo.replace("audit_db: var/audit.sqlite", "audit_db: /var/lib/pkwbus/audit.sqlite")
    return demo.rstrip() + "\n" + SERIAL_LINE


class Simulator:
    """`pkwbus simulate` on a pty: drives 1-3, 3 dead, corrupted and dropped answers."""

    def __init__(self, state: Path) -> None:
        self.link = state / "ttyline"
        self.log = (state / "simulator.log").open("wb")
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "pkwbus",
                "simulate",
                "--protocol",
                "fc",
                "--pty",
                str(self.link),
                "--drives",
                "1-3",
                "--dead",
                "3",
                "--catalog",
                "danfoss-fc",
                "--corrupt",
                "0.03",
                "--drop",
                "0.03",
                "--seed",
                "7",
            ],
            stdout=self.log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        on_exit(self.stop)
        wait_until("the simulator's pty", self.link.exists, 15)
        self.device = os.path.realpath(self.link)

    def device_options(self) -> list[str]:
        """--device passes the device in as a USB adapter's would be (device cgroup rule, a
        node with the host's owner and mode). A pty's slave side opens only through the devpts
        file system, not through a node made with mknod, so the host's node is also bound over
        it; a /dev/ttyUSB* needs --device alone."""
        return ["--device", f"{self.device}:/dev/ttyUSB0", "-v", f"{self.device}:/dev/ttyUSB0"]

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()


def start_line_container(state: Path, sim: Simulator, token: str) -> tuple[str, int]:
    """The demo's lines plus the serial line, the configuration mounted read-only and the
    simulator's pty passed in as /dev/ttyUSB0: its container and its port on 127.0.0.1."""
    name, volume, port = f"{PREFIX}-line", f"{PREFIX}-line-data", free_port()
    config = state / "line.yaml"
    config.write_text(line_config())
    config.chmod(0o644)
    on_exit(lambda: rm_volume(volume))
    on_exit(lambda: rm_container(name))
    podman(
        "run",
        "-d",
        "--name",
        name,
        *HARDENED,
        "-v",
        f"{volume}:/var/lib/pkwbus",
        "-v",
        f"{config}:/etc/pkwbus/config.yaml:ro",
        *sim.device_options(),
        "-e",
        "PKWBUS_WRITE_TOKEN",
        "-p",
        f"127.0.0.1:{port}:9725",
        IMAGE,
    )
    return name, port
