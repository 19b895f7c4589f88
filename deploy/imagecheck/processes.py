"""Subprocesses, podman, HTTP on 127.0.0.1, waiting, cleaning up, and podman's configuration."""

from __future__ import annotations

import contextlib
import json
import os
import resource
import socket
import subprocess
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .report import CheckFailed

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

cleanups: list[Callable[[], object]] = []


def on_exit(fn: Callable[[], object]) -> None:
    cleanups.append(fn)


def clean_up() -> None:
    """Undo what the checks started, the last started first; a failure stops none of it."""
    for fn in reversed(cleanups):
        with contextlib.suppress(Exception):
            fn()


def rm_container(name: str) -> None:
    podman("rm", "-f", "-t", "2", name, check=False)


def rm_volume(name: str) -> None:
    podman("volume", "rm", "-f", name, check=False)


# --- podman's configuration ---------------------------------------------------------


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


def containers_conf(state: Path) -> None:
    """A containers.conf of our own: runc, cgroupfs, ulimits within the machine's."""

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
