"""The hot standby stack (deploy/compose.standby.yaml) with podman-compose: three etcd
members made from Debian's etcd-server, a simulated gateway and two pkwbus instances of the
image just built. One instance masters the line; its container is killed (SIGKILL) and the
other masters the line within lease + 3 s (#47)."""

from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

from .build import drop_replaced, image_id
from .processes import free_port, http, on_exit, podman, run, wait_until
from .report import CheckFailed, expect, say, step
from .settings import (
    BASE_TAG,
    COMPOSE_STANDBY,
    ETCD_IMAGE,
    IMAGE,
    PREFIX,
    STANDBY_LEASE_S,
    TAKEOVER_LIMIT_S,
)

LINE = "hall1_line1"  # the line of deploy/compose.standby.config.yaml


def standby_checks(state: Path) -> None:
    with step(
        f"hot standby compose stack: the master container killed, the other masters "
        f"the line within lease + 3 s ({TAKEOVER_LIMIT_S:g} s)"
    ):
        check_standby(state)


def etcd_image(state: Path) -> None:
    """etcd from the Debian package in an image: the binary where the etcd project's image
    has it (/usr/local/bin/etcd), so that the compose file's command fits both."""
    ctx = state / "etcd-image"
    ctx.mkdir()
    binary = shutil.which("etcd") or "/usr/bin/etcd"
    if not os.access(binary, os.X_OK):
        raise CheckFailed("etcd is not installed (Debian package etcd-server)")
    shutil.copy(binary, ctx / "etcd")
    (ctx / "Containerfile").write_text(
        f"FROM {BASE_TAG}\n"
        "COPY etcd /usr/local/bin/etcd\n"
        "RUN mkdir -p /var/lib/etcd && chown 65534:65534 /var/lib/etcd\n"
        "USER 65534\nEXPOSE 2379 2380\n"
        'ENTRYPOINT []\nCMD ["/usr/local/bin/etcd"]\n'
    )
    before = image_id(ETCD_IMAGE)
    podman("build", "--format", "docker", "--pull=never", "-t", ETCD_IMAGE, str(ctx), timeout=300)
    drop_replaced(ETCD_IMAGE, before)


def series(port: int, name: str) -> float | None:
    """The value of ``name{line="hall1_line1"}`` on the instance's /metrics (None: absent)."""
    status, body = http(f"http://127.0.0.1:{port}/metrics", timeout=2)
    if status != 200:
        return None
    m = re.search(rf'^{name}\{{[^}}]*line="{LINE}"[^}}]*\}} (\S+)$', body.decode(), re.M)
    return float(m.group(1)) if m else None


def mastering(port: int) -> bool:
    try:
        return series(port, "pkwbus_line_master") == 1.0
    except OSError:
        return False


def check_standby(state: Path) -> None:
    etcd_image(state)
    override = state / "compose.standby.override.yaml"
    override.write_text(
        "services:\n"
        + "".join(f"  {s}:\n    image: {IMAGE}\n" for s in ("gateway", "pkwbus-a", "pkwbus-b"))
    )
    project = f"{PREFIX}-standby"
    base = ["podman-compose", "-p", project, "-f", str(COMPOSE_STANDBY), "-f", str(override)]
    ports = {"pkwbus-a": free_port(), "pkwbus-b": free_port()}
    env = {
        **os.environ,
        "ETCD_IMAGE": ETCD_IMAGE,
        "PKWBUS_A_PORT": str(ports["pkwbus-a"]),
        "PKWBUS_B_PORT": str(ports["pkwbus-b"]),
    }

    def down() -> None:
        run([*base, "down", "-v", "-t", "2"], check=False, env=env, timeout=120)

    def container(service: str) -> str:
        names = podman(
            "ps", "-a", "--filter", f"label=io.podman.compose.project={project}",
            "--filter", f"label=com.docker.compose.service={service}",
            "--format", "{{.Names}}",
        ).stdout.split()  # fmt: skip
        expect(len(names) == 1, f"containers of {service}: {names}")
        return names[0]

    def logs_of(*services: str) -> str:
        out = []
        for service in services:
            got = podman("logs", "--tail", "20", container(service), check=False)
            out.append(f"--- {service}\n{(got.stdout + got.stderr).strip()}")
        return "\n".join(out)

    on_exit(down)
    run([*base, "up", "-d", "--no-build"], env=env, timeout=240)

    def one_master() -> str | None:
        masters = [s for s, port in ports.items() if mastering(port)]
        return masters[0] if len(masters) == 1 else None

    try:
        master = wait_until("one instance mastering the line", one_master, 120, every=0.5)
        wait_until(
            f"{LINE} up on {master}",
            lambda: series(ports[master], "pkwbus_line_up") == 1.0,
            60,
            every=0.5,
        )
    except CheckFailed as exc:
        raise CheckFailed(f"{exc}\n{logs_of('pkwbus-a', 'pkwbus-b', 'etcd-0')}") from None
    other = next(s for s in ports if s != master)
    expect(not mastering(ports[other]), f"{other} masters the line too")
    say(f"    {master} masters {LINE}; {other} stands by (lease {STANDBY_LEASE_S:g} s)")
    killed = time.monotonic()
    podman("kill", "--signal", "KILL", container(master))
    try:
        wait_until(f"{other} mastering the line", lambda: mastering(ports[other]), 60, every=0.1)
    except CheckFailed as exc:
        raise CheckFailed(f"{exc}\n{logs_of(other)}") from None
    took = time.monotonic() - killed
    up = wait_until(
        f"{LINE} up on {other}",
        lambda: series(ports[other], "pkwbus_line_up") == 1.0,
        60,
        every=0.1,
    )
    line_up = time.monotonic() - killed
    say(
        f"    {master} killed: {other} masters the line after {took:.1f} s, "
        f"the line up there after {line_up:.1f} s"
    )
    expect(bool(up), f"{LINE} not up on {other}")
    expect(
        took <= TAKEOVER_LIMIT_S,
        f"{other} took the line {took:.1f} s after the kill, more than {TAKEOVER_LIMIT_S:g} s",
    )
    down()
