"""Builds the pkwbus image and checks it running; run by deploy/image-check.

    python deploy/image_check.py [--keep]

Run from the repository root, as root, with podman, buildah, runc and
debootstrap installed (deploy/image-check installs them). Every step prints
its time; the script exits 1 when any check fails. What it proves is listed
in docs/deploy.md ("What deploy/image-check proves").

Everything it starts listens on 127.0.0.1 or inside its own containers, and
it removes what it started (containers, pods, volumes, networks) on the way
out; --keep leaves them for a look.

The checks are in deploy/imagecheck/, one module a concern; this file runs them in order.
"""

from __future__ import annotations

import argparse
import os
import secrets
import shutil
import sys
import tempfile
import time
from pathlib import Path

from imagecheck.build import build, make_base
from imagecheck.containers import Simulator, start_line_container
from imagecheck.manifests import check_dashboard_sdk, static_checks
from imagecheck.processes import clean_up, containers_conf, containers_possible
from imagecheck.prometheus import Prometheus, check_alert, check_dashboard_queries
from imagecheck.report import exit_code, failed, say, skipped, step, summary
from imagecheck.service import (
    check_demo,
    check_device_group,
    check_image_config,
    check_line,
    check_no_config,
)
from imagecheck.settings import BASE_TAG, PREFIX
from imagecheck.stack import stack_checks
from imagecheck.standby import standby_checks


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
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
            clean_up()
            shutil.rmtree(state, ignore_errors=True)
        else:
            say(f"kept: {state} and the containers named {PREFIX}-*")
        summary(started)


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
        return exit_code()
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
    standby_checks(state)
    if prom is not None:
        with step("dashboard queries against Prometheus scraping the container"):
            check_dashboard_queries(prom)
        with step("alert PkwbusDriveDown fires for the dead drive (rules.yml as it is)"):
            # for: 2m after the drive is seen down, plus an evaluation or two.
            check_alert(prom, max(10.0, 180 - (time.time() - prom.started)))
    return exit_code()


if __name__ == "__main__":
    sys.exit(main())
