"""What the image must stay within, and the names and files the checks use."""

from __future__ import annotations

import os
from pathlib import Path

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
# What the base is made of; a change here (or in build.make_base) makes a new one.
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
COMPOSE_STANDBY = Path("deploy/compose.standby.yaml")
# etcd for the hot standby stack, from Debian's etcd-server (no registry needed).
ETCD_IMAGE = "localhost/pkwbus-check-etcd:debian"
# The lease of deploy/compose.standby.config.yaml, and what a takeover may take (#47).
STANDBY_LEASE_S = 4.0
TAKEOVER_LIMIT_S = STANDBY_LEASE_S + 3.0
K8S = Path("deploy/kubernetes")
SCHEMAS = Path("deploy/schemas")
DEMO = Path("config/demo.yaml")
