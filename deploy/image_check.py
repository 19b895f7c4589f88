"""Builds the pkwbus image and checks it running; run by deploy/image-check.

    python deploy/image_check.py [--keep]

Run from the repository root, as root, with podman, buildah, runc and
debootstrap installed (deploy/image-check installs them). Every step prints
its time; the script exits 1 when any check fails. What it proves is listed
in docs/deploy.md ("What deploy/image-check proves").

Everything it starts listens on 127.0.0.1 or inside its own containers, and
it removes what it started (containers, pods, volumes, networks) on the way
out; --keep leaves them for a look.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import re
import secrets
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import yaml

# --- what the image must stay within ----------------------------------------------

# The image built on the Debian-archive base was 174 MB (podman's size, the
# base included). The check fails when it grows by more than 20 %: look at what
# came in (a new dependency, build files left in a layer) before raising this.
IMAGE_SIZE_BASELINE_MB = 174
IMAGE_SIZE_LIMIT_MB = IMAGE_SIZE_BASELINE_MB * 1.2
SIGTERM_LIMIT_S = 5.0
HEALTH_LIMIT_S = 20.0

UID = 10001
DIALOUT_GID = 20  # the image's dialout, and Debian's and Ubuntu's
SUITE = "bookworm"
# Debian bookworm's python3 is 3.11: the base image is tagged for what it holds
# and the Dockerfile's PYTHON_VERSION is set to match.
PYTHON_VERSION = "3.11"
BASE_TAG = f"docker.io/library/python:{PYTHON_VERSION}-slim-{SUITE}"
# What the base is made of; a change here (or in make_base) makes a new one.
BASE_PACKAGES = (
    "python3",
    "python3-venv",
    "python-is-python3",
    "ca-certificates",
    "netbase",
    "tzdata",
)
BASE_RECIPE = "1"
CACHE_DIR = Path(os.environ.get("PKWBUS_IMAGE_CACHE", "/var/cache/pkwbus-image"))

IMAGE = "localhost/pkwbus:check"
# How docs/deploy.md runs the image: read-only root, no capabilities, no new privileges.
HARDENED = ("--read-only", "--cap-drop", "ALL", "--security-opt", "no-new-privileges")
PROM_IMAGE = "localhost/pkwbus-check-prometheus:debian"
PREFIX = f"pkwbus-check-{os.getpid()}"

DASHBOARD = Path("deploy/grafana/dashboards/pkwbus.json")
DATASOURCE = Path("deploy/grafana/provisioning/datasources/prometheus.yaml")
RULES = Path("deploy/prometheus/rules.yml")
COMPOSE = Path("deploy/compose.yaml")
K8S = Path("deploy/kubernetes")
SCHEMAS = Path("deploy/schemas")
DEMO = Path("config/demo.yaml")


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
                unit = every[number.end():] if number else ""
                if number and float(number.group()) * units.get(unit or "s", 1e9) <= seconds:
                    fast.add((drive["name"], str(poll["parameter"]).split("[")[0]))
    return fast


def rule_count() -> int:
    """How many alert and recording rules deploy/prometheus/rules.yml has."""
    return sum(len(group["rules"]) for group in yaml.safe_load(RULES.read_text())["groups"])

# --- output ---------------------------------------------------------------------

results: list[str] = []
failed: list[str] = []
skipped: list[str] = []


class CheckFailed(Exception):
    pass


def say(msg: str) -> None:
    print(msg, flush=True)


@contextlib.contextmanager
def step(name: str) -> Iterator[None]:
    """One timed step: ok, or FAIL with the reason; a failure does not stop the others."""
    start = time.monotonic()
    say(f"--- {name}")
    try:
        yield
    except CheckFailed as exc:
        took = time.monotonic() - start
        failed.append(name)
        results.append(f"FAIL  {name} ({took:.0f}s)")
        say(f"FAIL  {name}: {exc}")
    else:
        took = time.monotonic() - start
        results.append(f"ok    {name} ({took:.0f}s)")
        say(f"ok    {name} ({took:.1f}s)")


def expect(cond: bool, msg: str) -> None:
    if not cond:
        raise CheckFailed(msg)


# --- processes ------------------------------------------------------------------


def run(
    args: list[str],
    *,
    check: bool = True,
    timeout: float = 300,
    env: dict[str, str] | None = None,
    input_text: str | None = None,
) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(
        args, capture_output=True, text=True, timeout=timeout, env=env, input=input_text
    )
    if check and proc.returncode != 0:
        raise CheckFailed(
            f"{' '.join(args[:6])}... exited {proc.returncode}:\n"
            + (proc.stdout[-1500:] + proc.stderr[-2500:]).rstrip()
        )
    return proc


def podman(
    *args: str, check: bool = True, timeout: float = 300
) -> subprocess.CompletedProcess[str]:
    return run(["podman", *args], check=check, timeout=timeout)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def http(
    url: str,
    *,
    method: str = "GET",
    body: Any = None,
    headers: dict[str, str] | None = None,
    timeout: float = 5,
) -> tuple[int, bytes]:
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(url, data=data, method=method, headers=headers or {})
    if data is not None:
        req.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(req, timeout=timeout) as resp:
            return resp.status, resp.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def wait_until(what: str, check: Callable[[], Any], limit: float, every: float = 0.25) -> Any:
    deadline = time.monotonic() + limit
    last: Any = None
    while time.monotonic() < deadline:
        try:
            result = check()
        except (OSError, urllib.error.URLError, ValueError) as exc:
            result, last = None, exc
        if result:
            return result
        last = result if result is not None else last
        time.sleep(every)
    raise CheckFailed(f"timed out after {limit:.0f}s waiting for {what} (last: {last!r})")


def logs(name: str) -> str:
    out = podman("logs", "--tail", "30", name, check=False)
    return (out.stdout + out.stderr).strip()


# --- cleaning up ------------------------------------------------------------------

cleanups: list[Callable[[], None]] = []


def on_exit(fn: Callable[[], None]) -> None:
    cleanups.append(fn)


def rm_container(name: str) -> None:
    podman("rm", "-f", "-t", "2", name, check=False)


def rm_volume(name: str) -> None:
    podman("volume", "rm", "-f", name, check=False)


# --- podman's configuration ---------------------------------------------------------


def containers_conf(state: Path) -> None:
    """A containers.conf of our own: runc, cgroupfs, ulimits within the machine's."""
    import resource

    def limit(kind: int, name: str, most: int) -> str:
        _, hard = resource.getrlimit(kind)
        value = most if hard == resource.RLIM_INFINITY else min(hard, most)
        return f'"{name}={value}:{value}"'

    conf = state / "containers.conf"
    conf.write_text(
        "[containers]\n"
        # Rootful podman's defaults are above what many CI machines allow, and
        # without CAP_SYS_RESOURCE runc cannot raise them.
        f"default_ulimits = [{limit(resource.RLIMIT_NOFILE, 'nofile', 16384)}, "
        f"{limit(resource.RLIMIT_NPROC, 'nproc', 4096)}]\n"
        "[engine]\n"
        # crun refuses hybrid cgroup hierarchies; runc takes them.
        'runtime = "runc"\n'
        'cgroup_manager = "cgroupfs"\n'
        'events_logger = "file"\n'
    )
    os.environ["CONTAINERS_CONF"] = str(conf)


# --- the base image -------------------------------------------------------------------


def debian_mirror() -> str:
    sources = Path("/etc/apt/sources.list.d/debian.sources")
    if sources.is_file():
        for line in sources.read_text().splitlines():
            if line.startswith("URIs:") and "security" not in line:
                return line.split()[1]
    listfile = Path("/etc/apt/sources.list")
    if listfile.is_file():
        for line in listfile.read_text().splitlines():
            parts = line.split()
            if parts[:1] == ["deb"] and "security" not in line:
                return next(p for p in parts[1:] if "://" in p)
    return "http://deb.debian.org/debian"


def base_key() -> str:
    text = json.dumps([BASE_RECIPE, SUITE, BASE_PACKAGES, PYTHON_VERSION])
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def make_base() -> str:
    """The base image the Dockerfile starts from, made from the Debian archive.

    Debian's python3 on debootstrap's minbase, with /usr/local/bin/python as the
    python images have it. The root file system is cached as a tarball in
    CACHE_DIR, so a later run on this machine only imports it.
    """
    key = base_key()
    label = f"pkwbus.base-key={key}"
    have = podman(
        "image", "inspect", "--format", '{{index .Labels "pkwbus.base-key"}}', BASE_TAG, check=False
    )
    if have.returncode == 0 and have.stdout.strip() == key:
        return "present"
    tarball = CACHE_DIR / f"base-{SUITE}-python{PYTHON_VERSION}-{key}.tar"
    how = "from the cache"
    if not tarball.is_file():
        how = "from the Debian archive"
        CACHE_DIR.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=CACHE_DIR) as tmp:
            root = Path(tmp) / "rootfs"
            mirror = debian_mirror()
            say(f"    debootstrap --variant=minbase {SUITE} from {mirror}")
            run(
                [
                    "debootstrap",
                    "--variant=minbase",
                    f"--include={','.join(BASE_PACKAGES)}",
                    SUITE,
                    str(root),
                    mirror,
                ],
                timeout=900,
            )
            for junk in (
                "var/cache/apt",
                "var/lib/apt/lists",
                "usr/share/doc",
                "usr/share/man",
                "usr/share/info",
                "usr/share/locale",
                "var/log",
            ):
                shutil.rmtree(root / junk, ignore_errors=True)
                (root / junk).mkdir(parents=True, exist_ok=True)
            (root / "var/lib/apt/lists/partial").mkdir(parents=True, exist_ok=True)
            (root / "var/cache/apt/archives/partial").mkdir(parents=True, exist_ok=True)
            (root / "usr/local/bin").mkdir(parents=True, exist_ok=True)
            for name in ("python", "python3"):
                link = root / "usr/local/bin" / name
                link.unlink(missing_ok=True)
                link.symlink_to("/usr/bin/python3")
            # No host name or resolver of the build machine in the image.
            (root / "etc/hostname").write_text("localhost\n")
            (root / "etc/resolv.conf").unlink(missing_ok=True)
            partial = tarball.with_suffix(".partial")
            run(["tar", "--numeric-owner", "-C", str(root), "-cf", str(partial), "."], timeout=300)
            partial.rename(tarball)
    podman(
        "import",
        "--change",
        f"LABEL {label}",
        "--change",
        "ENV LANG=C.UTF-8",
        "--change",
        "ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
        "--change",
        'CMD ["python3"]',
        str(tarball),
        BASE_TAG,
    )
    return how


# --- building -------------------------------------------------------------------------


def pip_mounts(state: Path) -> list[str]:
    """-v options giving pip inside the build this machine's index and CA bundle, read-only.

    Nothing of it lands in a layer: podman build's -v mounts only exist while a
    RUN instruction runs.
    """
    out = run([sys.executable, "-m", "pip", "config", "list"], check=False).stdout
    conf: dict[str, str] = {}
    for line in out.splitlines():
        key, _, value = line.partition("=")
        conf[key.split(".", 1)[-1]] = value.strip().strip("'\"")
    for env, key in (
        ("PIP_INDEX_URL", "index-url"),
        ("PIP_EXTRA_INDEX_URL", "extra-index-url"),
        ("PIP_TRUSTED_HOST", "trusted-host"),
        ("PIP_CERT", "cert"),
        ("PIP_PROXY", "proxy"),
        ("PIP_DEFAULT_TIMEOUT", "timeout"),
    ):
        if os.environ.get(env):
            conf[key] = os.environ[env]
    lines = ["[global]"]
    for key in ("index-url", "extra-index-url", "trusted-host", "proxy", "timeout"):
        if key in conf:
            # Local directories of this machine are not in the build container.
            value = " ".join(u for u in conf[key].split() if not u.startswith("file:"))
            if value:
                lines.append(f"{key} = {value}")
    mounts: list[str] = []
    bundle = conf.get("cert") or os.environ.get("SSL_CERT_FILE") or ""
    if not bundle and Path("/etc/ssl/certs/ca-certificates.crt").is_file():
        bundle = "/etc/ssl/certs/ca-certificates.crt"
    if bundle and Path(bundle).is_file():
        mounts += ["-v", f"{Path(bundle).resolve()}:/etc/ssl/certs/ca-certificates.crt:ro"]
        lines.append("cert = /etc/ssl/certs/ca-certificates.crt")
    pipconf = state / "pip.conf"
    pipconf.write_text("\n".join(lines) + "\n")
    mounts += ["-v", f"{pipconf}:/etc/pip.conf:ro"]
    return mounts


def image_id(ref: str) -> str:
    out = podman("image", "inspect", "--format", "{{.Id}}", ref, check=False)
    return out.stdout.strip() if out.returncode == 0 else ""


def drop_replaced(ref: str, before: str) -> None:
    """Remove the image a rebuild untagged, so runs do not pile up old images."""
    if before and image_id(ref) != before:
        podman("rmi", before, check=False)


def build(state: Path) -> None:
    before = image_id(IMAGE)
    args = [
        "build",
        "--format",
        "docker",
        "--build-arg",
        f"PYTHON_VERSION={PYTHON_VERSION}",
        "--pull=never",
        *pip_mounts(state),
        "-t",
        IMAGE,
        "-f",
        "Dockerfile",
        ".",
    ]
    proc = podman(*args, check=False, timeout=900)
    if proc.returncode != 0:
        raise CheckFailed("podman build failed:\n" + (proc.stdout + proc.stderr)[-4000:])
    drop_replaced(IMAGE, before)


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
        return bool(drive and parameter) and (drive[1], parameter[1]) in fast

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
    demo = Path("config/demo.yaml").read_text()
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


def start_line_container(state: Path, sim: Simulator, token: str) -> tuple[str, int]:
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


# --- Prometheus on this machine, scraping the container ----------------------------------


def scrape_interval() -> str:
    """The datasource's timeInterval: Grafana's $__rate_interval is computed from it."""
    ds = yaml.safe_load(DATASOURCE.read_text())["datasources"][0]
    return str(ds.get("jsonData", {}).get("timeInterval", "15s"))


class Prometheus:
    def __init__(self, state: Path, target: str) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        interval = scrape_interval()
        conf = state / "prometheus.yml"
        shutil.copy(RULES, state / "rules.yml")
        conf.write_text(
            f"global:\n  scrape_interval: {interval}\n  evaluation_interval: {interval}\n"
            "rule_files: [rules.yml]\n"
            "scrape_configs:\n  - job_name: pkwbus\n"
            f"    static_configs:\n      - targets: ['{target}']\n"
        )
        self.log = (state / "prometheus.log").open("wb")
        self.proc = subprocess.Popen(
            [
                shutil.which("prometheus") or "/usr/bin/prometheus",
                f"--config.file={conf}",
                f"--storage.tsdb.path={state / 'tsdb'}",
                f"--web.listen-address=127.0.0.1:{self.port}",
            ],
            stdout=self.log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self.started = time.time()
        on_exit(self.stop)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()

    def api(self, path: str, **params: Any) -> Any:
        query = urllib.parse.urlencode(params)
        status, body = http(f"{self.url}/api/v1/{path}?{query}", timeout=10)
        data = json.loads(body)
        if status != 200 or data.get("status") != "success":
            raise CheckFailed(f"{path} {params}: {status} {data.get('error', body[:300])}")
        return data["data"]


def duration_s(text: str) -> float:
    units = {"ms": 0.001, "s": 1, "m": 60, "h": 3600, "d": 86400}
    m = re.fullmatch(r"(\d+(?:\.\d+)?)(ms|s|m|h|d)", text.strip())
    if not m:
        raise ValueError(f"not a duration: {text!r}")
    return float(m.group(1)) * units[m.group(2)]


def round_interval(seconds: float) -> float:
    """Grafana's roundInterval: the calculated $__interval, rounded to a readable step."""
    steps = [
        (0.015, 0.01),
        (0.035, 0.02),
        (0.075, 0.05),
        (0.15, 0.1),
        (0.35, 0.2),
        (0.75, 0.5),
        (1.5, 1),
        (3.5, 2),
        (7.5, 5),
        (12.5, 10),
        (17.5, 15),
        (25, 20),
        (45, 30),
        (90, 60),
        (210, 120),
        (450, 300),
        (750, 600),
        (1050, 900),
        (1500, 1200),
        (2700, 1800),
        (5400, 3600),
        (9000, 7200),
        (16200, 10800),
        (32400, 21600),
    ]
    return next((step for limit, step in steps if seconds <= limit), 43200)


def fmt_s(seconds: float) -> str:
    return f"{int(seconds)}s" if seconds >= 1 else f"{int(seconds * 1000)}ms"


def panels(ps: list[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    for p in ps:
        yield p
        yield from panels(p.get("panels", []))


def check_dashboard_queries(prom: Prometheus) -> None:
    """Every query of the dashboard, as Grafana sends it with the variables at All."""
    dash = json.loads(DASHBOARD.read_text())
    scrape = duration_s(scrape_interval())

    # Enough scrapes for the windows of rate() ([5m] needs two samples).
    def scraped() -> bool:
        result = prom.api("query", query='count_over_time(up{job="pkwbus"}[5m])')["result"]
        return bool(result) and float(result[0]["value"][1]) >= 8

    wait_until("8 scrapes of the container", scraped, 20 * scrape, every=1)
    now = time.time()
    span = duration_s(dash["time"]["from"].removeprefix("now-"))
    start = now - span
    variables: dict[str, str] = {}
    for var in dash["templating"]["list"]:
        if var["type"] != "query":
            continue
        query = var["query"]["query"] if isinstance(var["query"], dict) else var["query"]
        for k, v in variables.items():
            query = query.replace(f"${k}", v)
        m = re.fullmatch(r"label_values\((.*),\s*(\w+)\)", query.strip())
        expect(m is not None, f"variable {var['name']}: not label_values(): {query}")
        assert m is not None
        values = prom.api(
            f"label/{m.group(2)}/values",
            **{"match[]": m.group(1), "start": f"{start:.0f}", "end": f"{now:.0f}"},
        )
        expect(bool(values), f"variable {var['name']}: {query} has no values")
        say(f"    ${var['name']}: {len(values)} values ({', '.join(values[:6])})")
        variables[var["name"]] = var.get("allValue") or "(" + "|".join(map(re.escape, values)) + ")"

    checked = 0
    empty: list[str] = []
    for panel in panels(dash["panels"]):
        max_points = panel.get("maxDataPoints") or 1000
        min_interval = duration_s(panel["interval"]) if panel.get("interval") else scrape
        interval = max(min_interval, round_interval(span / max_points))
        rate_interval = max(interval + scrape, 4 * scrape)
        for target in panel.get("targets", []):
            expr = target["expr"]
            for k in sorted(variables, key=len, reverse=True):
                expr = expr.replace(f"${{{k}}}", variables[k]).replace(f"${k}", variables[k])
            for k, v in (
                ("__rate_interval", rate_interval),
                ("__interval", interval),
                ("__range", span),
            ):
                expr = expr.replace(f"${{{k}}}", fmt_s(v)).replace(f"${k}", fmt_s(v))
            expect("$" not in expr, f"{panel['title']}: unreplaced variable in {expr}")
            where = f"{panel['title']!r} {target.get('refId')}"
            legend = set(re.findall(r"\{\{\s*(\w+)\s*\}\}", target.get("legendFormat") or ""))
            instant = prom.api("query", query=expr, time=f"{now:.3f}")["result"]
            step = max(interval, 1)
            ranged = prom.api(
                "query_range",
                query=expr,
                start=f"{start - start % step:.0f}",
                end=f"{now - now % step:.0f}",
                step=fmt_s(step),
            )["result"]
            for kind, result in (("instant", instant), ("range", ranged)):
                if not result:
                    continue
                # A label no series has is a wrong name; a label some series lack is one
                # whose value is empty there (Prometheus drops empty labels), shown blank.
                seen = set().union(*(s["metric"] for s in result))
                expect(
                    legend <= seen,
                    f"{where} ({kind}): no series has the legend's label(s)"
                    f" {sorted(legend - seen)}: {result[0]['metric']}",
                )
                blank = {lbl for s in result for lbl in legend - set(s["metric"])}
                if blank and kind == "instant":
                    say(f"    note: {where}: some series have an empty {', '.join(sorted(blank))}")
            if not instant or not ranged:
                empty.append(where)
            checked += 1
    say(
        f"    {checked} queries, instant and range ($__rate_interval {fmt_s(rate_interval)}"
        f" for scrape {fmt_s(scrape)})"
    )
    # Only the panels of tripped drives, of active alarms and of changed settings may be
    # empty: the simulated drives trip and are set at their keypads at random
    # (pkwbus_drive_alarm and pkwbus_drive_setting_changed have no series while none is).
    allowed = {
        "'Tripped drives' A",
        "'Active alarms and warnings' A",
        "'Settings changed from their baseline' A",
    }
    if empty:
        say(f"    no data: {', '.join(empty)}")
    expect(set(empty) <= allowed, f"queries without data: {sorted(set(empty) - allowed)}")


def check_alert(prom: Prometheus, wait_s: float) -> None:
    def firing() -> Any:
        alerts = prom.api("alerts")["alerts"]
        down = [a for a in alerts if a["labels"]["alertname"] == "PkwbusDriveDown"]
        return down if any(a["state"] == "firing" for a in down) else None

    rules = prom.api("rules")["groups"]
    count = sum(len(g["rules"]) for g in rules)
    bad = [
        r["name"]
        for g in rules
        for r in g["rules"]
        if r.get("health") != "ok" and r.get("lastEvaluation", "").startswith("0001") is False
    ]
    say(f"    {count} rules loaded, unhealthy: {bad or 'none'}")
    expect(not bad, f"rules fail to evaluate: {bad}")
    down = wait_until("PkwbusDriveDown firing", firing, wait_s, every=2)
    drives = sorted(a["labels"]["drive"] for a in down)
    states = sorted(a["state"] for a in down)
    say(f"    PkwbusDriveDown {states} for {drives}")
    expect(drives == ["dead_press"], f"PkwbusDriveDown for {drives}, not only dead_press")


# --- the dashboard JSON against the Grafana SDK ---------------------------------------------


# Keys Grafana writes into dashboards that the SDK's models leave out: the
# built-in annotation marker and a query variable's display text.
SDK_UNMODELLED = {"builtIn", "definition"}


def check_dashboard_sdk() -> None:
    """Round-trip the dashboard through grafana-foundation-sdk's models: a key it drops is a typo
    or a field Grafana does not know."""
    from grafana_foundation_sdk.cog import plugins
    from grafana_foundation_sdk.cog.encoder import JSONEncoder
    from grafana_foundation_sdk.models.dashboard import Dashboard

    plugins.register_default_plugins()
    original = json.loads(DASHBOARD.read_text())
    problems = sdk_diff(original, Dashboard, JSONEncoder)
    expect(not problems, "dashboard keys the SDK does not know:\n  " + "\n  ".join(problems))
    # The check must catch a typo: it is run on a damaged copy too.
    damaged = json.loads(DASHBOARD.read_text())
    next(p for p in panels(damaged["panels"]) if p.get("targets"))["targets"][0]["legendFromat"] = 1
    damaged["panels"][0]["gridPoss"] = damaged["panels"][0].pop("gridPos")
    caught = sdk_diff(damaged, Dashboard, JSONEncoder)
    say(f"    round trip keeps every key; two typos in a copy caught: {len(caught)} problem(s)")
    expect(len(caught) >= 2, f"typos not caught: {caught}")


def sdk_diff(original: dict[str, Any], model: Any, encoder: Any) -> list[str]:
    try:
        again = json.loads(json.dumps(model.from_json(original), cls=encoder))
    except (KeyError, TypeError, ValueError) as exc:
        return [f"the SDK cannot read the dashboard: {exc!r}"]
    problems: list[str] = []

    def walk(a: Any, b: Any, path: str) -> None:
        if isinstance(a, dict):
            if not isinstance(b, dict):
                problems.append(f"{path}: became {type(b).__name__}")
                return
            for k, v in a.items():
                if k not in b:
                    problems.append(f"{path}.{k}")
                else:
                    walk(v, b[k], f"{path}.{k}")
        elif isinstance(a, list) and isinstance(b, list):
            for i, (x, y) in enumerate(zip(a, b, strict=False)):
                walk(x, y, f"{path}[{i}]")

    walk(original, again, "$")
    return [p for p in problems if p.rsplit(".", 1)[-1] not in SDK_UNMODELLED]


# --- compose and Kubernetes --------------------------------------------------------------


def validator(schema: dict[str, Any]) -> Any:
    import jsonschema  # only in the tools venv

    cls = jsonschema.validators.validator_for(schema, default=jsonschema.Draft7Validator)
    return cls(schema)


def schema_errors(v: Any, doc: Any) -> list[str]:
    return [
        f"{'/'.join(map(str, e.absolute_path)) or '(top)'}: {e.message[:160]}"
        for e in v.iter_errors(doc)
    ]


def crd_validator(name: str, version: str) -> Any:
    crd = yaml.safe_load((SCHEMAS / name).read_text())
    spec = next(v for v in crd["spec"]["versions"] if v["name"] == version)
    return validator(spec["schema"]["openAPIV3Schema"])


def kustomize() -> list[dict[str, Any]]:
    out = run(["kubectl", "kustomize", str(K8S)], timeout=60).stdout
    return [d for d in yaml.safe_load_all(out) if d]


def static_checks() -> None:
    with step("compose file valid against the compose-spec schema"):
        v = validator(json.loads((SCHEMAS / "compose-spec.json").read_text()))
        compose = yaml.safe_load(COMPOSE.read_text())
        errors = schema_errors(v, compose)
        expect(not errors, "\n  ".join(errors))
        damaged = json.loads(json.dumps(compose))
        damaged["services"]["pkwbus"]["read_onyl"] = True
        expect(bool(schema_errors(v, damaged)), "the schema does not catch a misspelt key")
        say(f"    {COMPOSE}: valid; a misspelt key in a copy is caught")
    with step(
        "kubectl kustomize renders; ServiceMonitor and PrometheusRule valid against the CRDs"
    ):
        docs = kustomize()
        kinds = sorted(f"{d['kind']}/{d['metadata']['name']}" for d in docs)
        say(f"    {len(docs)} objects: {', '.join(kinds)}")
        checked = 0
        for d in docs:
            crd = {
                "ServiceMonitor": "monitoring.coreos.com_servicemonitors.yaml",
                "PrometheusRule": "monitoring.coreos.com_prometheusrules.yaml",
            }.get(d["kind"])
            if crd is None:
                continue
            v = crd_validator(crd, d["apiVersion"].split("/")[1])
            errors = schema_errors(v, d)
            expect(not errors, f"{d['kind']} {d['metadata']['name']}:\n  " + "\n  ".join(errors))
            checked += 1
        expect(checked == 2, f"{checked} of ServiceMonitor and PrometheusRule rendered")
        rule = next(d for d in docs if d["kind"] == "PrometheusRule")
        expect(
            rule["spec"]["groups"] == yaml.safe_load(RULES.read_text())["groups"],
            "the PrometheusRule's groups differ from deploy/prometheus/rules.yml",
        )
        monitor = json.loads(json.dumps(next(d for d in docs if d["kind"] == "ServiceMonitor")))
        monitor["spec"]["endpoints"][0]["port"] = 9725
        expect(
            bool(
                schema_errors(
                    crd_validator("monitoring.coreos.com_servicemonitors.yaml", "v1"), monitor
                )
            ),
            "the CRD schema does not catch a numeric port name",
        )
        maps = [d for d in docs if d["kind"] == "ConfigMap"]
        expect(
            all(re.search(r"-[a-z0-9]{10}$", m["metadata"]["name"]) for m in maps),
            "ConfigMaps without a content hash in their name",
        )
        say(
            "    ServiceMonitor and PrometheusRule valid (a wrong type in a copy is caught);"
            " ConfigMaps named by content hash"
        )


def stack_checks(state: Path) -> None:
    with step("podman-compose up: pkwbus and Prometheus, target up, rules loaded"):
        check_compose(state)
    with step("podman kube play gateway-1: /readyz 503 without the gateway, 200 with it"):
        check_kube_play(state)


def prometheus_image(state: Path) -> None:
    """Prometheus from the Debian package in an image, for the compose file's prometheus."""
    ctx = state / "prometheus-image"
    ctx.mkdir()
    shutil.copy(shutil.which("prometheus") or "/usr/bin/prometheus", ctx / "prometheus")
    (ctx / "Containerfile").write_text(
        f"FROM {BASE_TAG}\n"
        "COPY prometheus /bin/prometheus\n"
        "RUN mkdir -p /prometheus /etc/prometheus && chown 65534:65534 /prometheus\n"
        "USER 65534\nWORKDIR /prometheus\nEXPOSE 9090\n"
        'ENTRYPOINT ["/bin/prometheus"]\n'
        'CMD ["--config.file=/etc/prometheus/prometheus.yml", "--storage.tsdb.path=/prometheus"]\n'
    )
    before = image_id(PROM_IMAGE)
    podman("build", "--format", "docker", "--pull=never", "-t", PROM_IMAGE, str(ctx), timeout=300)
    drop_replaced(PROM_IMAGE, before)


def check_compose(state: Path) -> None:
    prometheus_image(state)
    override = state / "compose.override.yaml"
    override.write_text(
        f"services:\n  pkwbus:\n    image: {IMAGE}\n  prometheus:\n    image: {PROM_IMAGE}\n"
    )
    project = f"{PREFIX}-compose"
    base = ["podman-compose", "-p", project, "-f", str(COMPOSE), "-f", str(override)]
    pkwbus_port, prom_port = free_port(), free_port()
    env = {**os.environ, "PKWBUS_PORT": str(pkwbus_port), "PROMETHEUS_PORT": str(prom_port)}

    def down() -> None:
        run([*base, "down", "-v", "-t", "2"], check=False, env=env, timeout=120)

    on_exit(down)
    run([*base, "up", "-d", "--no-build", "pkwbus", "prometheus"], env=env, timeout=180)
    url = f"http://127.0.0.1:{prom_port}/api/v1"

    def target_up() -> Any:
        status, body = http(f"{url}/targets")
        targets = json.loads(body)["data"]["activeTargets"] if status == 200 else []
        up = [t for t in targets if t["labels"].get("job") == "pkwbus" and t["health"] == "up"]
        return up or None

    try:
        up = wait_until("Prometheus's target pkwbus up", target_up, 60, every=1)
    except CheckFailed as exc:
        ps = run(
            ["podman", "ps", "-a", "--filter", f"label=io.podman.compose.project={project}"],
            check=False,
        ).stdout
        raise CheckFailed(f"{exc}\n{ps}") from None
    status, body = http(f"{url}/rules")
    groups = json.loads(body)["data"]["groups"]
    rules = [r for g in groups for r in g["rules"]]
    health = {r.get("health") for r in rules}
    say(
        f"    target {up[0]['scrapeUrl']} up; {len(rules)} rules loaded "
        f"(health {', '.join(sorted(map(str, health)))})"
    )
    expected = rule_count()
    expect(len(rules) == expected, f"{len(rules)} rules loaded, not {expected}")
    status, _ = http(f"http://127.0.0.1:{pkwbus_port}/readyz")
    expect(status == 200, f"pkwbus /readyz on the published port answered {status}")
    took = time.monotonic()
    down()
    left = run(
        ["podman", "ps", "-a", "-q", "--filter", f"label=io.podman.compose.project={project}"],
        check=False,
    ).stdout.split()
    say(f"    torn down in {time.monotonic() - took:.1f}s")
    expect(not left, f"containers left after down: {left}")


def check_kube_play(state: Path) -> None:
    """gateway-1 as kustomize renders it, the image set to the one built here, the gateway's
    name pointing at the pod itself, where a simulator is started later."""
    docs = kustomize()
    deployment = next(
        d for d in docs if d["kind"] == "Deployment" and d["metadata"]["name"] == "pkwbus-gateway-1"
    )
    pod = deployment["spec"]["template"]["spec"]
    config_name = next(v["configMap"]["name"] for v in pod["volumes"] if "configMap" in v)
    configmap = next(
        d for d in docs if d["kind"] == "ConfigMap" and d["metadata"]["name"] == config_name
    )
    config = yaml.safe_load(configmap["data"]["config.yaml"])
    gateway = urllib.parse.urlsplit(config["lines"][0]["port"])
    name = f"{PREFIX}-gw1"
    deployment["metadata"]["name"] = name
    pod["containers"][0]["image"] = IMAGE
    pod["hostAliases"] = [{"ip": "127.0.0.1", "hostnames": [gateway.hostname]}]
    claim = next(v for v in pod["volumes"] if "persistentVolumeClaim" in v)
    pvc = next(
        d
        for d in docs
        if d["kind"] == "PersistentVolumeClaim"
        and d["metadata"]["name"] == claim["persistentVolumeClaim"]["claimName"]
    )
    pvc["metadata"]["name"] = claim["persistentVolumeClaim"]["claimName"] = f"{name}-data"
    kube = state / "gateway-1.kube.yaml"
    kube.write_text(yaml.safe_dump_all([configmap, pvc, deployment], sort_keys=False))
    on_exit(lambda: rm_volume(f"{name}-data"))
    on_exit(lambda: rm_volume(config_name))  # podman keeps a ConfigMap volume under its name
    on_exit(lambda: podman("kube", "down", str(kube), check=False))
    podman("kube", "play", str(kube), timeout=120)
    # podman names the pod NAME-pod-0 (4.3) or NAME-pod (later), its containers POD-CONTAINER.
    pod_name = podman(
        "pod", "ps", "--filter", f"name=^{name}-pod", "--format", "{{.Name}}"
    ).stdout.split()[0]
    container = f"{pod_name}-pkwbus"
    probe = [
        "exec",
        container,
        "python",
        "-c",
        "import urllib.request as u, urllib.error as e\n"
        "try: print(u.urlopen('http://127.0.0.1:9725/readyz', timeout=3).status)\n"
        "except e.HTTPError as x: print(x.code)",
    ]

    def readyz() -> int | None:
        out = podman(*probe, check=False)
        return int(out.stdout.strip()) if out.returncode == 0 and out.stdout.strip() else None

    try:
        first = wait_until("the pod's /readyz", readyz, 30)
    except CheckFailed as exc:
        raise CheckFailed(f"{exc}\n{logs(container)}") from None
    time.sleep(2)
    second = readyz()
    say(f"    /readyz without the gateway: {first}, {second}")
    expect(first == 503 and second == 503, f"/readyz {first}, {second} while the gateway is down")
    drives = ",".join(str(d["address"]) for d in config["lines"][0]["drives"])
    podman(
        "run",
        "-d",
        "--pod",
        pod_name,
        "--name",
        f"{name}-gateway",
        "--no-healthcheck",
        "--entrypoint",
        "pkwbus",
        IMAGE,
        "simulate",
        "--protocol",
        "fc",
        "--listen",
        f"tcp://127.0.0.1:{gateway.port}",
        "--drives",
        drives,
        "--catalog",
        "danfoss-fc",
    )
    on_exit(lambda: rm_container(f"{name}-gateway"))
    started = time.monotonic()
    try:
        wait_until("/readyz 200 with the gateway", lambda: readyz() == 200, 60, every=1)
    except CheckFailed as exc:
        raise CheckFailed(f"{exc}\n{logs(container)}") from None
    say(f"    /readyz 200 {time.monotonic() - started:.1f}s after the simulated gateway started")


# --- main -------------------------------------------------------------------------------------


def containers_possible() -> str | None:
    """None when this machine can run containers, else why not."""
    probe = run(
        ["unshare", "--user", "--map-root-user", "--mount", "--pid", "--fork", "true"],
        check=False,
        timeout=30,
    )
    if probe.returncode != 0:
        return f"no user namespaces ({probe.stderr.strip() or 'unshare failed'})"
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--keep", action="store_true", help="leave containers and volumes")
    args = parser.parse_args()
    started = time.monotonic()
    os.environ["PKWBUS_WRITE_TOKEN"] = token = secrets.token_hex(16)
    state = Path(tempfile.mkdtemp(prefix="pkwbus-image-check-"))
    state.chmod(0o755)
    try:
        return checks(state, token)
    finally:
        if not args.keep:
            for fn in reversed(cleanups):
                with contextlib.suppress(Exception):
                    fn()
            shutil.rmtree(state, ignore_errors=True)
        else:
            say(f"kept: {state} and the containers named {PREFIX}-*")
        say("\n".join(results))
        total = time.monotonic() - started
        verdict = f"FAILED: {', '.join(failed)}" if failed else "all checks passed"
        if skipped:
            verdict += f"; SKIPPED: {skipped[0]}"
        say(f"deploy/image-check: {verdict} ({total:.0f}s)")


def checks(state: Path, token: str) -> int:
    with step("dashboard JSON round-trips through grafana-foundation-sdk"):
        check_dashboard_sdk()
    static_checks()
    why_not = containers_possible()
    if why_not:
        skipped.append(f"the container checks ({why_not})")
        say(
            f"deploy/image-check: SKIPPED the container checks: this machine cannot run "
            f"containers: {why_not}"
        )
        return 1 if failed else 0
    containers_conf(state)
    with step(f"base image {BASE_TAG}"):
        say(f"    {make_base()}")
    with step("podman build --format docker (the Dockerfile unchanged)"):
        build(state)
    if failed:
        return 1
    with step("image: numeric non-root USER in dialout, HEALTHCHECK, size"):
        check_image_config()
    sim = prom = None
    line = ("", 0)
    with step("simulated serial line on a pty, passed with --device"):
        sim = Simulator(state)
        check_device_group(sim)
        line = start_line_container(state, sim, token)
        prom = Prometheus(state, f"127.0.0.1:{line[1]}")
    with step(
        "demo configuration: read-only root, no capabilities, health, metrics, audit, SIGTERM"
    ):
        check_demo(token)
    with step("no configuration: exit 2 with a clear message"):
        check_no_config()
    if line[1]:
        with step("serial device opened without --group-add; dead drive seen"):
            check_line(*line, token)
    stack_checks(state)
    if prom is not None:
        with step("dashboard queries against Prometheus scraping the container"):
            check_dashboard_queries(prom)
        with step("alert PkwbusDriveDown fires for the dead drive (rules.yml as it is)"):
            # for: 2m after the drive is seen down, plus an evaluation or two.
            check_alert(prom, max(10.0, 180 - (time.time() - prom.started)))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
