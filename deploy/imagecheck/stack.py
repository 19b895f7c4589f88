"""The compose stack (pkwbus and a Prometheus made from the Debian package) with
podman-compose, and gateway-1's manifests in podman kube play."""

from __future__ import annotations

import json
import os
import shutil
import time
import urllib.parse
from pathlib import Path
from typing import Any

import yaml

from .build import drop_replaced, image_id
from .manifests import kustomize
from .processes import (
    free_port,
    http,
    logs,
    on_exit,
    podman,
    rm_container,
    rm_volume,
    run,
    wait_until,
)
from .report import CheckFailed, expect, say, step
from .settings import BASE_TAG, COMPOSE, IMAGE, PREFIX, PROM_IMAGE, RULES


def rule_count() -> int:
    """How many alert and recording rules deploy/prometheus/rules.yml has."""
    return sum(len(group["rules"]) for group in yaml.safe_load(RULES.read_text())["groups"])


def stack_checks(state: Path) -> None:
    with step("podman-compose up: pkwbus and Prometheus, target up, rules loaded"):
        check_compose(state)
    with step("podman kube play gateway-1: /readyz 503 without the gateway, 200 with it"):
        check_kube_play(state)


# --- compose ------------------------------------------------------------------------------


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


# --- Kubernetes ----------------------------------------------------------------------------


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
