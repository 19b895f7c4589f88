"""The image and the running service: user, groups, capabilities, read-only root,
HEALTHCHECK, size, metrics, the API's write and its audit entry, SIGTERM, the serial line."""

from __future__ import annotations

import contextlib
import json
import os
import re
import sqlite3
import time
from pathlib import Path
from typing import Any

import yaml

from .containers import Simulator, start_demo
from .processes import http, logs, podman, wait_until
from .report import CheckFailed, expect, say
from .settings import (
    DEMO,
    DIALOUT_GID,
    IMAGE,
    IMAGE_SIZE_BASELINE_MB,
    IMAGE_SIZE_LIMIT_MB,
    SIGTERM_LIMIT_S,
    UID,
)

# --- the demo configuration --------------------------------------------------------


def demo_drives() -> int:
    """How many drives the demo configuration has, on all its lines."""
    return sum(len(line["drives"]) for line in yaml.safe_load(DEMO.read_text())["lines"])


def demo_fast_polls(seconds: float = 2.0) -> set[tuple[str, str]]:
    """The (drive, parameter) pairs the demo configuration polls at least every
    ``seconds`` (not the alarm words and counters polled by default, slowly)."""
    units = {"ms": 0.001, "s": 1.0, "m": 60.0, "h": 3600.0}
    fast = set()
    for line in yaml.safe_load(DEMO.read_text())["lines"]:
        for drive in line["drives"]:
            for poll in drive.get("poll", []):
                every = str(poll["every"])
                number = re.match(r"[\d.]+", every)
                unit = every[number.end() :] if number else ""
                if number and float(number.group()) * units.get(unit or "s", 1e9) <= seconds:
                    fast.add((drive["name"], str(poll["parameter"]).split("[")[0]))
    return fast


# --- the image ------------------------------------------------------------------------


def check_image_config() -> None:
    info = json.loads(podman("image", "inspect", IMAGE).stdout)[0]
    size_mb = info["Size"] / 1e6
    say(
        f"    image size {size_mb:.0f} MB (budget {IMAGE_SIZE_LIMIT_MB:.0f} MB = "
        f"{IMAGE_SIZE_BASELINE_MB} MB + 20 %)"
    )
    config = info.get("Config", {})
    user = config.get("User", "")
    expect(user.isdigit() and int(user) != 0, f"USER is {user!r}, not a numeric non-root uid")
    health = info.get("Healthcheck") or config.get("Healthcheck") or {}
    expect(
        bool(health.get("Test")), "the image has no HEALTHCHECK (built without --format docker?)"
    )
    expect(
        size_mb <= IMAGE_SIZE_LIMIT_MB,
        f"image is {size_mb:.0f} MB, over the budget of {IMAGE_SIZE_LIMIT_MB:.0f} MB",
    )
    ident = podman(
        "run", "--rm", "--no-healthcheck", "--network", "none", "--entrypoint", "id", IMAGE
    ).stdout.strip()
    say(f"    id: {ident}")
    expect(f"uid={UID}(" in ident, f"runs as {ident}, not uid {UID}")
    expect(f"{DIALOUT_GID}(dialout)" in ident, f"uid {UID} is not in dialout: {ident}")


# --- the running service ---------------------------------------------------------------


def proc_status(name: str) -> dict[str, str]:
    text = podman("exec", name, "cat", "/proc/1/status").stdout
    return {k: v.strip() for k, _, v in (line.partition(":") for line in text.splitlines())}


def metrics(port: int) -> str:
    status, body = http(f"http://127.0.0.1:{port}/metrics")
    expect(status == 200, f"/metrics answered {status}")
    return body.decode()


def samples(text: str, name: str) -> dict[str, float]:
    """{label text: value} of metric ``name`` in an exposition."""
    out: dict[str, float] = {}
    for m in re.finditer(rf"^{name}(\{{[^}}]*\}})? (\S+)$", text, re.M):
        out[m.group(1) or ""] = float(m.group(2))
    return out


def check_demo(token: str) -> None:
    """The image's own demo configuration, hardened as docs/deploy.md says."""
    name, volume, port = start_demo()

    status = proc_status(name)
    uids = status["Uid"].split()
    groups = status["Groups"].split()
    say(
        f"    process: Uid {uids[0]}, Groups {' '.join(groups)}, CapEff {status['CapEff']}, "
        f"NoNewPrivs {status.get('NoNewPrivs')}"
    )
    expect(uids == [str(UID)] * 4, f"process uids {uids}, not {UID}")
    expect(str(DIALOUT_GID) in groups, f"process not in dialout: groups {groups}")
    expect(
        int(status["CapEff"], 16) == 0 and int(status["CapPrm"], 16) == 0,
        f"process has capabilities: CapEff {status['CapEff']}",
    )
    root_write = podman("exec", name, "sh", "-c", "touch /probe", check=False)
    expect(
        root_write.returncode != 0 and "Read-only" in root_write.stderr,
        f"the root file system is writable: {root_write.stderr.strip()!r}",
    )

    health = podman("healthcheck", "run", name, check=False)
    say(f"    podman healthcheck run: exit {health.returncode} {health.stdout.strip()}")
    expect(health.returncode == 0, f"HEALTHCHECK fails: {health.stdout}{health.stderr}")

    def live() -> bool:
        text = metrics(port)
        up = samples(text, "pkwbus_drive_up")
        stamps = samples(text, "pkwbus_parameter_last_update_timestamp_seconds")
        return len(up) == drives and all(v == 1 for v in up.values()) and len(stamps) > 0

    drives = demo_drives()
    wait_until(f"all {drives} demo drives up", live, 30)
    # The values the demo polls every second or two (not the alarm words and counters
    # polled by default every 30 or 60 s): within 11 s at least half are read again.
    fast = demo_fast_polls()

    def polled_fast(labels: str) -> bool:
        drive = re.search(r'drive="([^"]*)"', labels)
        parameter = re.search(r'parameter="([^"]*)"', labels)
        return drive is not None and parameter is not None and (drive[1], parameter[1]) in fast

    stamp = "pkwbus_parameter_last_update_timestamp_seconds"

    def fast_values() -> dict[str, float]:
        return {k: v for k, v in samples(metrics(port), stamp).items() if polled_fast(k)}

    # Up is not yet described: a drive's first values wait for its descriptions (of the
    # polled parameters and of its swept settings), which the alarm words do not.
    first = wait_until("the values the demo polls fast exported", fast_values, 30)
    time.sleep(11.0)
    second = samples(metrics(port), stamp)
    moved = [k for k in first if second.get(k, 0) > first[k]]
    values = samples(metrics(port), "pkwbus_parameter_value")
    say(
        f"    {len(values)} parameter values; of the {len(first)} polled every 2 s at most,"
        f" {len(moved)} updated in 11 s"
    )
    expect(len(first) > 0, "none of the values the demo polls every 2 s at most is exported")
    expect(len(moved) >= len(first) // 2, "values are not being updated")

    auth = {"Authorization": f"Bearer {token}"}
    status_code, body = http(
        f"http://127.0.0.1:{port}/api/v1/drives/supply_fan/parameters/3-41",
        method="PUT",
        body={"value": 7.5},
        headers=auth,
        timeout=10,
    )
    expect(status_code == 200, f"write through the API answered {status_code}: {body[:300]!r}")
    mount = podman("volume", "inspect", "--format", "{{.Mountpoint}}", volume).stdout.strip()
    found = list(Path(mount).rglob("audit.sqlite"))
    expect(bool(found), f"no audit.sqlite on the volume {volume} ({mount})")
    with contextlib.closing(sqlite3.connect(f"file:{found[0]}?mode=ro", uri=True)) as db:
        tables = [r[0] for r in db.execute("select name from sqlite_master where type='table'")]
        rows = sum(db.execute(f'select count(*) from "{t}"').fetchone()[0] for t in tables)
    say(f"    audit database on the volume: {found[0].relative_to(mount)}, {rows} row(s)")
    expect(rows >= 1, "the audit database on the volume has no entry for the write")

    started = time.monotonic()
    podman("kill", "--signal", "TERM", name)
    code = podman("wait", name, timeout=30).stdout.strip()
    took = time.monotonic() - started
    say(f"    SIGTERM: exit {code} after {took:.1f}s")
    expect(code == "0", f"exit status {code} after SIGTERM, not 0:\n{logs(name)}")
    expect(took <= SIGTERM_LIMIT_S, f"took {took:.1f}s to stop, over {SIGTERM_LIMIT_S:.0f}s")


def check_no_config() -> None:
    proc = podman(
        "run", "--rm", "--no-healthcheck", "--network", "none", IMAGE, check=False, timeout=60
    )
    message = (proc.stderr + proc.stdout).strip()
    say(f"    exit {proc.returncode}: {message[:200]}")
    expect(proc.returncode == 2, f"exit {proc.returncode}, not 2")
    expect("/etc/pkwbus/config.yaml" in message, "the message does not name the missing file")
    expect("Traceback" not in message, "a traceback reached the user")


# --- the serial line ---------------------------------------------------------------------


def check_device_group(sim: Simulator) -> None:
    """The device's group decides: dialout opens it without --group-add, root's does not."""
    opener = [
        "run",
        "--rm",
        "--no-healthcheck",
        "--network",
        "none",
        *sim.device_options(),
        "--entrypoint",
        "python",
        IMAGE,
        "-c",
        "import os; os.close(os.open('/dev/ttyUSB0', os.O_RDWR | os.O_NOCTTY)); print('open')",
    ]
    os.chown(sim.device, 0, 0)
    os.chmod(sim.device, 0o660)
    denied = podman(*opener, check=False)
    os.chown(sim.device, 0, DIALOUT_GID)
    allowed = podman(*opener, check=False)
    say(f"    device group root: exit {denied.returncode}; group dialout: {allowed.stdout.strip()}")
    expect(denied.returncode != 0, "a root:root 0660 device opened: the check proves nothing")
    expect(allowed.returncode == 0, f"a dialout device did not open: {allowed.stderr[-500:]}")


def check_line(name: str, port: int, token: str) -> None:
    def state() -> Any:
        text = metrics(port)
        up = samples(text, "pkwbus_drive_up")
        line = samples(text, "pkwbus_line_up")
        serial = {k: v for k, v in up.items() if 'line="serial_line"' in k}
        if line.get('{line="serial_line"}') != 1 or len(serial) != 3:
            return None
        alive = [k for k, v in serial.items() if v == 1]
        dead = [k for k, v in serial.items() if v == 0]
        return (alive, dead) if len(alive) == 2 and len(dead) == 1 else None

    try:
        _, dead = wait_until("line up, 2 drives up and 1 down", state, 30)
    except CheckFailed as exc:
        raise CheckFailed(f"{exc}\n{logs(name)}") from None
    say(f"    serial_line up on /dev/ttyUSB0 (no --group-add); down: {dead[0]}")
    expect("dead_press" in dead[0], f"the wrong drive is down: {dead}")
    auth = {"Authorization": f"Bearer {token}"}
    status, body = http(
        f"http://127.0.0.1:{port}/api/v1/drives/press_1/parameters/3-41",
        method="PUT",
        body={"value": 3.0},
        headers=auth,
        timeout=10,
    )
    expect(status == 200, f"write on the serial line answered {status}: {body[:300]!r}")
