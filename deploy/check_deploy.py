"""Consistency checks for the deployment files, run by deploy/check.

    python deploy/check_deploy.py --structure   compose, Grafana, Kubernetes wiring
    python deploy/check_deploy.py --metrics     PromQL names only interface metrics
    python deploy/check_deploy.py --promql      dashboard PromQL parses (promtool)

Run from the repository root. Needs PyYAML. Prints one line per problem and
exits 1 if there is any.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml

DEPLOY = Path("deploy")
DASHBOARD = DEPLOY / "grafana" / "dashboards" / "pkwbus.json"
RULES = DEPLOY / "prometheus" / "rules.yml"
RULES_TEST = DEPLOY / "prometheus" / "rules_test.yml"
COMPOSE = DEPLOY / "compose.yaml"
COMPOSE_STANDBY = DEPLOY / "compose.standby.yaml"
K8S = DEPLOY / "kubernetes"

# The metric table of interface.md, for when the shared design folder is not
# beside the repository. interface.md wins when it is found.
FALLBACK_METRICS = {
    "pkwbus_parameter_value",
    "pkwbus_parameter_info",
    "pkwbus_parameter_last_update_timestamp_seconds",
    "pkwbus_pkw_faults_total",
    "pkwbus_telegram_errors_total",
    "pkwbus_telegrams_total",
    "pkwbus_jobs_total",
    "pkwbus_job_retries_total",
    "pkwbus_transaction_duration_seconds",
    "pkwbus_drive_up",
    "pkwbus_drive_status_word",
    "pkwbus_drive_status_bit",
    "pkwbus_line_up",
    "pkwbus_line_busy_seconds_total",
    "pkwbus_poll_overruns_total",
    "pkwbus_dp_slave_state",
    "pkwbus_dp_restarts_total",
    "pkwbus_dp_diagnostics_total",
    "pkwbus_build_info",
    "pkwbus_drive_alarm",
    "pkwbus_drive_events_total",
    "pkwbus_drive_setting_changed",
    "pkwbus_drive_settings_swept_timestamp_seconds",
    "pkwbus_config_last_reload_successful",
    "pkwbus_config_last_reload_success_timestamp_seconds",
    "pkwbus_drive_maintenance",
    "pkwbus_line_master",
    "pkwbus_standby_etcd_up",
    "pkwbus_standby_takeovers_total",
}

# In the interface's table but not exported yet, each named in README.md's metric
# section as open work: hot standby on etcd is a capability still to come.
NOT_YET_EXPORTED: set[str] = set()
HISTOGRAM_SUFFIXES = ("_bucket", "_sum", "_count")

# Exported beyond the interface's table, each documented in README.md's metric
# table: the HTTP API's own counters, the main actual value that comes with
# each status word, and when the newest entry of a drive's own log was found (what
# an alert of its first fault needs). The dashboard and the rules may name them too.
BEYOND_INTERFACE = {
    "pkwbus_drive_event_newest_timestamp_seconds",
    "pkwbus_audit_errors_total",
    "pkwbus_api_refusals_total",
    "pkwbus_drive_main_actual_percent",
    "pkwbus_drive_pkw_length_conflict",
    "pkwbus_catalog_mismatch",
    # Named in the interface's text, not its table: how late the event loop runs.
    "pkwbus_event_loop_lag_seconds",
}

# Status word bit names (bit label of pkwbus_drive_status_bit).
FC_BITS = {
    "control_ready",
    "drive_ready",
    "enabled",
    "trip",
    "error",
    "trip_lock",
    "warning",
    "at_reference",
    "bus_control",
    "frequency_within_limit",
    "running",
}
PROFIDRIVE_BITS = {
    "ready_to_switch_on",
    "ready",
    "operation_enabled",
    "fault",
    "no_coast_stop",
    "no_quick_stop",
    "switching_on_inhibited",
    "warning",
    "speed_within_tolerance",
    "control_requested",
    "reference_reached",
}

METRIC_RE = re.compile(r"\bpkwbus_[a-z_]+")
BIT_MATCHER_RE = re.compile(r'\bbit\s*(=~|=|!~|!=)\s*"([^"]*)"')

problems: list[str] = []


def problem(msg: str) -> None:
    problems.append(msg)
    print(f"  {msg}")


def load_yaml_docs(path: Path) -> list[Any]:
    with path.open() as f:
        return [d for d in yaml.safe_load_all(f) if d is not None]


# --- interface metrics ---------------------------------------------------------


def interface_md() -> Path | None:
    env = os.environ.get("PKWBUS_INTERFACE_MD")
    candidates = [Path(env)] if env else []
    candidates += [Path("../shared/design/interface.md"), Path("shared/design/interface.md")]
    return next((p for p in candidates if p.is_file()), None)


def interface_metrics() -> tuple[set[str], str]:
    path = interface_md()
    if path is None:
        return FALLBACK_METRICS, "built-in list (interface.md not found)"
    names = set(re.findall(r"^\|\s*`(pkwbus_[a-z_]+)`", path.read_text(), re.M))
    if not names:
        problem(f"{path}: no metric table rows found")
        return FALLBACK_METRICS, "built-in list"
    return names, str(path)


def dashboard_exprs(dash: dict[str, Any]) -> Iterator[tuple[str, str]]:
    def panels(ps: list[dict[str, Any]]) -> Iterator[dict[str, Any]]:
        for p in ps:
            yield p
            yield from panels(p.get("panels", []))

    for p in panels(dash.get("panels", [])):
        for t in p.get("targets", []):
            if "expr" in t:
                yield f"panel {p.get('title')!r} {t.get('refId')}", t["expr"]
    for v in dash.get("templating", {}).get("list", []):
        q = v.get("query")
        if isinstance(q, dict):
            q = q.get("query")
        if v.get("type") == "query" and isinstance(q, str):
            yield f"variable {v.get('name')}", q


def rule_exprs(rules: dict[str, Any]) -> Iterator[tuple[str, str]]:
    for g in rules.get("groups", []):
        for r in g.get("rules", []):
            yield f"rule {r.get('alert') or r.get('record')}", str(r["expr"])


def test_series(tests: dict[str, Any]) -> Iterator[tuple[str, str]]:
    for i, t in enumerate(tests.get("tests", [])):
        for s in t.get("input_series", []):
            yield f"rules_test tests[{i}] input series", s["series"]


def check_metrics() -> None:
    known, source = interface_metrics()
    readme = Path("README.md").read_text()
    for name in sorted(BEYOND_INTERFACE):
        if f"`{name}" not in readme:
            problem(f"README.md: {name} is exported beyond the interface but not documented")
    known = known | BEYOND_INTERFACE
    dash = json.loads(DASHBOARD.read_text())
    rules = yaml.safe_load(RULES.read_text())
    tests = yaml.safe_load(RULES_TEST.read_text())
    where = [
        (DASHBOARD, list(dashboard_exprs(dash))),
        (RULES, list(rule_exprs(rules))),
        (RULES_TEST, list(test_series(tests))),
    ]
    used: set[str] = set()
    count = 0
    for path, exprs in where:
        for place, expr in exprs:
            count += 1
            for name in METRIC_RE.findall(expr):
                base = name
                for suffix in HISTOGRAM_SUFFIXES:
                    if name.endswith(suffix) and name[: -len(suffix)] in known:
                        base = name[: -len(suffix)]
                used.add(base)
                if base not in known:
                    problem(f"{path}: {place}: {name} is not in the interface ({source})")
            for op, value in BIT_MATCHER_RE.findall(expr):
                bits = value.split("|") if "~" in op else [value]
                for bit in bits:
                    if bit not in FC_BITS | PROFIDRIVE_BITS:
                        problem(f"{path}: {place}: status bit {bit!r} is not an FC/PROFIdrive bit")
    unused = sorted(known - used)
    print(f"  {count} expressions, {len(used)} metrics used; metric list from {source}")
    if unused:
        print(f"  not shown anywhere (fine, informational): {', '.join(unused)}")


# --- dashboard PromQL syntax ------------------------------------------------------

GRAFANA_VARS = {
    "$__rate_interval": "1m",
    "$__interval": "1m",
    "$__range": "1h",
}


def check_promql(promtool: str) -> None:
    dash = json.loads(DASHBOARD.read_text())
    rules = []
    for i, (place, expr) in enumerate(dashboard_exprs(dash)):
        if expr.startswith("label_values("):
            m = re.fullmatch(r"label_values\((.*),\s*\w+\)", expr, re.S)
            if not m:
                problem(f"{DASHBOARD}: {place}: cannot read {expr!r}")
                continue
            expr = m.group(1)
        for var, value in GRAFANA_VARS.items():
            expr = expr.replace(f"[{var}]", f"[{value}]")
        expr = re.sub(r"\$\{?(\w+)\}?", r"\1", expr)  # $line inside "..." stays a string
        rules.append({"record": f"dashboard:expr_{i}", "expr": expr, "labels": {"at": place}})
    with tempfile.NamedTemporaryFile("w", suffix=".yml", delete=False) as f:
        yaml.safe_dump({"groups": [{"name": "dashboard", "rules": rules}]}, f)
        tmp = f.name
    try:
        r = subprocess.run([promtool, "check", "rules", tmp], capture_output=True, text=True)
    finally:
        os.unlink(tmp)
    if r.returncode != 0:
        problem(f"{DASHBOARD}: promtool rejects a query:\n{r.stdout}{r.stderr}")
    else:
        print(f"  {len(rules)} dashboard queries parse")


# --- structure ---------------------------------------------------------------------


def check_compose() -> None:
    compose = yaml.safe_load(COMPOSE.read_text())
    services = compose.get("services", {})
    for name in ("pkwbus", "prometheus", "grafana"):
        if name not in services:
            problem(f"{COMPOSE}: no service {name}")
    for name, svc in services.items():
        for vol in svc.get("volumes", []):
            src = vol.split(":", 1)[0]
            if src.startswith((".", "/")) and not (DEPLOY / src).exists():
                problem(f"{COMPOSE}: {name}: mounted {src} does not exist")
        build = svc.get("build")
        if build:
            ctx = DEPLOY / build.get("context", ".")
            if not (ctx / build.get("dockerfile", "Dockerfile")).is_file():
                problem(f"{COMPOSE}: {name}: no Dockerfile in build context {ctx}")
    pk = services.get("pkwbus", {})
    cmd = " ".join(pk.get("command", []))
    dockerfile = Path("Dockerfile").read_text()
    m = re.search(r"--config\s+(\S+)", cmd)
    if not m or f" {m.group(1)}" not in dockerfile:
        problem(f"{COMPOSE}: pkwbus command {cmd!r} does not run the demo config the image has")
    if "0.0.0.0:9725" not in cmd:
        problem(f"{COMPOSE}: pkwbus must listen on 0.0.0.0:9725 in a container")


def check_compose_standby() -> None:
    """The hot standby stack: two or more pkwbus instances with names of their own on one
    configuration, whose etcd members and gateway are services of the same file."""
    compose = yaml.safe_load(COMPOSE_STANDBY.read_text())
    services = compose.get("services", {})
    instances = {
        name: svc
        for name, svc in services.items()
        if "run" in svc.get("command", []) and "PKWBUS_INSTANCE" in svc.get("environment", {})
    }
    names = [svc["environment"]["PKWBUS_INSTANCE"] for svc in instances.values()]
    if len(instances) < 2 or len(set(names)) != len(names):
        problem(f"{COMPOSE_STANDBY}: not two instances with names of their own: {names}")
    configs = {
        vol.split(":")[0]
        for svc in instances.values()
        for vol in svc.get("volumes", [])
        if vol.split(":")[1:2] == ["/etc/pkwbus/config.yaml"]
    }
    if len(configs) != 1:
        problem(f"{COMPOSE_STANDBY}: the instances do not share one configuration: {configs}")
        return
    source = DEPLOY / configs.pop()
    if not source.is_file():
        problem(f"{COMPOSE_STANDBY}: mounted {source} does not exist")
        return
    config = yaml.safe_load(source.read_text())
    hosts = [re.sub(r"^https?://", "", u).split(":")[0] for u in config["standby"]["etcd"]]
    hosts += [re.sub(r"^\w+://", "", line["port"]).split(":")[0] for line in config["lines"]]
    for host in hosts:
        if host not in services:
            problem(f"{source}: {host} is no service of {COMPOSE_STANDBY}")
    advertised = [
        svc["environment"].get("PKWBUS_ADVERTISE") or config["standby"].get("advertise")
        for svc in instances.values()
    ]
    if None in advertised or (
        "{name}" not in str(advertised[0]) and len(set(advertised)) != len(advertised)
    ):
        problem(
            f"{COMPOSE_STANDBY}: each instance needs a URL of its own"
            f" (PKWBUS_ADVERTISE): {advertised}"
        )
    if "0.0.0.0:9725" not in " ".join(next(iter(instances.values()))["command"]):
        problem(f"{COMPOSE_STANDBY}: pkwbus must listen on 0.0.0.0:9725 in a container")


def check_grafana() -> None:
    dash = json.loads(DASHBOARD.read_text())
    ids = [p["id"] for p in dash.get("panels", [])]
    if len(ids) != len(set(ids)):
        problem(f"{DASHBOARD}: panel ids repeat")
    for p in dash.get("panels", []):
        if p.get("type") != "row" and not any(t.get("expr") for t in p.get("targets", [])):
            problem(f"{DASHBOARD}: panel {p.get('title')!r} has no query")
    ds_dir = DEPLOY / "grafana" / "provisioning" / "datasources"
    uids = {
        d.get("uid")
        for f in ds_dir.glob("*.yaml")
        for d in yaml.safe_load(f.read_text())["datasources"]
    }
    ds_var = [v for v in dash["templating"]["list"] if v.get("type") == "datasource"]
    if not ds_var or ds_var[0]["current"]["value"] not in uids:
        problem(f"{DASHBOARD}: datasource variable does not default to a provisioned uid {uids}")
    prov_dir = DEPLOY / "grafana" / "provisioning" / "dashboards"
    paths = {
        p["options"]["path"]
        for f in prov_dir.glob("*.yaml")
        for p in yaml.safe_load(f.read_text())["providers"]
    }
    compose = yaml.safe_load(COMPOSE.read_text())
    targets = {
        v.split(":")[1]
        for v in compose["services"]["grafana"]["volumes"]
        if v.startswith("./grafana/dashboards")
    }
    if not paths & targets:
        problem(
            f"{prov_dir}: provider path {paths} is not where compose mounts the dashboards"
            f" {targets}"
        )


def labels_match(selector: dict[str, str], labels: dict[str, str]) -> bool:
    return all(labels.get(k) == v for k, v in selector.items())


def check_kubernetes() -> None:
    docs: list[tuple[Path, dict[str, Any]]] = []
    kustomization = yaml.safe_load((K8S / "kustomization.yaml").read_text())
    for res in kustomization.get("resources", []):
        if not (K8S / res).is_file():
            problem(f"{K8S}/kustomization.yaml: resource {res} does not exist")
            continue
        docs += [(K8S / res, d) for d in load_yaml_docs(K8S / res)]
    # The gateways' ConfigMaps come from files through configMapGenerator.
    for gen in kustomization.get("configMapGenerator", []):
        data = {}
        for spec in gen.get("files", []):
            key, _, src = spec.rpartition("=")
            if not (K8S / src).is_file():
                problem(f"{K8S}/kustomization.yaml: configMapGenerator {gen['name']}: no {src}")
                continue
            data[key or Path(src).name] = (K8S / src).read_text()
        cm = {"kind": "ConfigMap", "metadata": {"name": gen["name"]}, "data": data}
        docs.append((K8S / "kustomization.yaml", cm))
    by_kind: dict[str, dict[str, dict[str, Any]]] = {}
    for _, d in docs:
        by_kind.setdefault(d["kind"], {})[d["metadata"]["name"]] = d
    configmaps = by_kind.get("ConfigMap", {})
    pvcs = by_kind.get("PersistentVolumeClaim", {})
    services = by_kind.get("Service", {})
    # pkwbus's workloads: its Deployments and its StatefulSets (a hot standby group
    # keeping each pod's audit database); the other StatefulSets are etcd's.
    deployments = {
        f"{kind} {name}": d
        for kind in ("Deployment", "StatefulSet")
        for name, d in by_kind.get(kind, {}).items()
        if d["spec"]["template"]["metadata"]["labels"].get("app.kubernetes.io/name") == "pkwbus"
    }
    if not by_kind.get("Deployment"):
        problem(f"{K8S}: no Deployment")
    secret_names = {d["metadata"]["name"] for d in load_yaml_docs(K8S / "secret.example.yaml")}
    for where, dep in deployments.items():
        spec = dep["spec"]
        pod = spec["template"]["spec"]
        standby = deployment_config(dep, configmaps).get("standby")
        if standby:
            check_standby_group(where, dep, standby, by_kind)
        elif dep["kind"] != "Deployment":
            problem(f"{where}: a single instance is a Deployment (replicas 1, Recreate)")
        else:
            if spec.get("replicas") != 1:
                problem(f"{where}: replicas must be 1 (one master per RS-485 line)")
            if spec.get("strategy", {}).get("type") != "Recreate":
                problem(f"{where}: strategy must be Recreate (no two masters during an update)")
        if not pod.get("securityContext", {}).get("runAsNonRoot"):
            problem(f"{where}: pod securityContext.runAsNonRoot is not true")
        volumes = {v["name"]: v for v in pod.get("volumes", [])}
        volumes |= {  # a StatefulSet's own claims: one per pod
            t["metadata"]["name"]: {"volumeClaimTemplate": t}
            for t in spec.get("volumeClaimTemplates", [])
            if dep["kind"] == "StatefulSet"
        }
        for v in volumes.values():
            if "configMap" in v and v["configMap"]["name"] not in configmaps:
                problem(f"{where}: ConfigMap {v['configMap']['name']} not defined")
            if "persistentVolumeClaim" in v and v["persistentVolumeClaim"]["claimName"] not in pvcs:
                problem(f"{where}: PVC {v['persistentVolumeClaim']['claimName']} not defined")
        for c in pod["containers"]:
            cw = f"{where} container {c['name']}"
            sc = c.get("securityContext", {})
            if not sc.get("readOnlyRootFilesystem"):
                problem(f"{cw}: readOnlyRootFilesystem is not true")
            if sc.get("allowPrivilegeEscalation") is not False:
                problem(f"{cw}: allowPrivilegeEscalation is not false")
            if sc.get("capabilities", {}).get("drop") != ["ALL"]:
                problem(f"{cw}: capabilities.drop is not [ALL]")
            env = {e["name"]: e for e in c.get("env", [])}
            for e in env.values():
                ref = e.get("valueFrom", {}).get("secretKeyRef")
                if ref and ref["name"] not in secret_names:
                    problem(
                        f"{cw}: Secret {ref['name']} is not the one secret.example.yaml describes"
                    )
            ports = {p.get("name"): p["containerPort"] for p in c.get("ports", [])}
            mounts = {m["mountPath"]: m for m in c.get("volumeMounts", [])}
            cfg_mount = mounts.get("/etc/pkwbus")
            if not cfg_mount or "configMap" not in volumes[cfg_mount["name"]]:
                problem(f"{cw}: /etc/pkwbus is not mounted from a ConfigMap")
                continue
            cm = configmaps[volumes[cfg_mount["name"]]["configMap"]["name"]]
            check_service_config(cw, cm, env, ports, mounts)
            if standby:
                check_standby_audit(cw, cm, mounts, volumes)
    services = {  # pkwbus's own; etcd.yaml's Service is checked with its StatefulSet
        name: svc
        for name, svc in services.items()
        if svc["metadata"].get("labels", {}).get("app.kubernetes.io/name") == "pkwbus"
    }
    for name, svc in services.items():
        sel = svc["spec"].get("selector", {})
        pods = [
            d
            for d in deployments.values()
            if labels_match(sel, d["spec"]["template"]["metadata"]["labels"])
        ]
        if len(pods) != 1:
            problem(f"Service {name}: selector {sel} matches {len(pods)} workloads, not 1")
        if not svc["spec"].get("publishNotReadyAddresses"):
            problem(
                f"Service {name}: publishNotReadyAddresses must be true"
                " (scrape while /readyz is 503)"
            )
    for name, sm in by_kind.get("ServiceMonitor", {}).items():
        sel = sm["spec"]["selector"].get("matchLabels", {})
        matched = [
            s for s in services.values() if labels_match(sel, s["metadata"].get("labels", {}))
        ]
        if len(matched) != len(services):
            problem(f"ServiceMonitor {name}: selects {len(matched)} of {len(services)} Services")
        for ep in sm["spec"]["endpoints"]:
            for s in matched:
                if ep["port"] not in {p.get("name") for p in s["spec"]["ports"]}:
                    problem(
                        f"ServiceMonitor {name}: Service {s['metadata']['name']}"
                        f" has no port {ep['port']}"
                    )
        job_label = sm["spec"].get("jobLabel")
        if any(s["metadata"]["labels"].get(job_label) != "pkwbus" for s in matched):
            problem(
                f"ServiceMonitor {name}: job label would not be 'pkwbus'"
                ' (rules select job="pkwbus")'
            )
    check_etcd_policy(by_kind)
    print(f"  {len(docs)} Kubernetes objects, {len(deployments)} pkwbus workloads wired up")


def deployment_config(dep: dict[str, Any], configmaps: dict[str, Any]) -> dict[str, Any]:
    """The pkwbus configuration a Deployment mounts at /etc/pkwbus ({} when none is found)."""
    pod = dep["spec"]["template"]["spec"]
    for v in pod.get("volumes", []):
        cm = configmaps.get(v.get("configMap", {}).get("name"))
        if cm is not None and "config.yaml" in cm.get("data", {}):
            return dict(yaml.safe_load(cm["data"]["config.yaml"]) or {})
    return {}


def check_standby_group(
    where: str, dep: dict[str, Any], standby: dict[str, Any], by_kind: dict[str, Any]
) -> None:
    """A hot standby group: two or more replicas, a PodDisruptionBudget that keeps one,
    each pod named from its own pod name, and etcd endpoints that are members here."""
    spec = dep["spec"]
    replicas = spec.get("replicas", 1)
    if replicas < 2:
        problem(f"{where}: a hot standby group needs 2 replicas or more, not {replicas}")
    labels = spec["template"]["metadata"]["labels"]
    budgets = [
        b
        for b in by_kind.get("PodDisruptionBudget", {}).values()
        if labels_match(b["spec"]["selector"].get("matchLabels", {}), labels)
    ]
    if not budgets:
        problem(f"{where}: no PodDisruptionBudget keeps one of its pods through a drain")
    for b in budgets:
        keeps = b["spec"].get("minAvailable", replicas - b["spec"].get("maxUnavailable", 0))
        if not 1 <= int(keeps) < replicas:
            problem(f"PodDisruptionBudget {b['metadata']['name']}: keeps {keeps} of {replicas}")
    for c in spec["template"]["spec"]["containers"]:
        env = {e["name"]: e for e in c.get("env", [])}
        field = env.get("PKWBUS_INSTANCE", {}).get("valueFrom", {}).get("fieldRef", {})
        if field.get("fieldPath") != "metadata.name":
            problem(f"{where} container {c['name']}: PKWBUS_INSTANCE is not the pod's name")
    check_advertise(where, dep, standby, by_kind)
    statefulsets = {  # etcd's
        name: s
        for name, s in by_kind.get("StatefulSet", {}).items()
        if s["spec"]["template"]["metadata"]["labels"].get("app.kubernetes.io/name") != "pkwbus"
    }
    members = {
        f"{s['metadata']['name']}-{i}.{s['spec']['serviceName']}"
        for s in statefulsets.values()
        for i in range(s["spec"].get("replicas", 1))
    }
    endpoints = standby.get("etcd", [])
    if len(endpoints) < 3:
        problem(f"{where}: standby.etcd names {len(endpoints)} members: list all three")
    for url in endpoints:
        host = re.sub(r"^https?://", "", str(url)).split(":")[0]
        if not any(host == m or host.startswith(m + ".") for m in members):
            problem(f"{where}: standby.etcd {url} is no etcd member of these manifests")
    for name, sts in statefulsets.items():
        if sts["spec"]["serviceName"] not in by_kind.get("Service", {}):
            problem(f"StatefulSet {name}: no Service {sts['spec']['serviceName']}")
        if sts["spec"].get("replicas") != 3:
            problem(f"StatefulSet {name}: etcd needs 3 members (one may be lost)")
        budgets = [
            b
            for b in by_kind.get("PodDisruptionBudget", {}).values()
            if labels_match(
                b["spec"]["selector"].get("matchLabels", {}),
                sts["spec"]["template"]["metadata"]["labels"],
            )
        ]
        if [b["spec"].get("maxUnavailable") for b in budgets] != [1]:
            problem(f"StatefulSet {name}: one PodDisruptionBudget with maxUnavailable 1")


def check_service_config(
    where: str,
    cm: dict[str, Any],
    env: dict[str, Any],
    ports: dict[str | None, int],
    mounts: dict[str, Any],
) -> None:
    cfg = yaml.safe_load(cm["data"]["config.yaml"])
    where = f"{where}: ConfigMap {cm['metadata']['name']} config.yaml"
    token_env = cfg.get("api", {}).get("write_token_env")
    if token_env not in env:
        problem(f"{where}: api.write_token_env {token_env!r} is not set in the container env")
    audit = str(cfg.get("audit_db", ""))
    writable = [p for p, m in mounts.items() if not m.get("readOnly")]
    if not audit.startswith("/") or not any(
        audit.startswith(p.rstrip("/") + "/") for p in writable
    ):
        problem(f"{where}: audit_db {audit!r} is not on a writable volume {writable}")
    listen = str(cfg.get("listen", ""))
    if not listen.endswith(f":{ports.get('http')}") or not listen.startswith("0.0.0.0:"):
        problem(f"{where}: listen {listen!r} does not serve containerPort http {ports.get('http')}")
    drives: list[str] = []
    for i, line in enumerate(cfg.get("lines", [])):
        if not str(line.get("port", "")).startswith(("socket://", "rfc2217://")):
            problem(f"{where}: lines[{i}].port must be a socket:// or rfc2217:// gateway URL")
        drives += [d["name"] for d in line.get("drives", [])]
    if len(drives) != len(set(drives)):
        problem(f"{where}: drive names repeat")


def check_standby_audit(
    where: str, cm: dict[str, Any], mounts: dict[str, Any], volumes: dict[str, Any]
) -> None:
    """A hot standby pod's audit database is its own and outlives the pod: on a
    StatefulSet's volumeClaimTemplate (one claim per pod), not an emptyDir."""
    audit = str(yaml.safe_load(cm["data"]["config.yaml"]).get("audit_db", ""))
    holders = [
        volumes.get(m["name"], {})
        for p, m in mounts.items()
        if audit.startswith(p.rstrip("/") + "/")
    ]
    if not any("volumeClaimTemplate" in v for v in holders):
        problem(
            f"{where}: audit_db {audit!r} is not on a volumeClaimTemplate"
            " (a StatefulSet keeps each pod's audit rows across restarts)"
        )


def check_advertise(
    where: str, dep: dict[str, Any], standby: dict[str, Any], by_kind: dict[str, Any]
) -> None:
    """Each pod of a group advertises its own URL (a 409 not_master names it): with
    ``{name}`` (PKWBUS_ADVERTISE or standby.advertise), under the StatefulSet's
    headless Service, whose one DNS name per pod it is."""
    for c in dep["spec"]["template"]["spec"]["containers"]:
        env = {e["name"]: e for e in c.get("env", [])}
        template = env.get("PKWBUS_ADVERTISE", {}).get("value") or standby.get("advertise")
        if not template or "{name}" not in str(template):
            problem(f"{where} container {c['name']}: no advertise URL with {{name}} per pod")
            continue
        if dep["kind"] != "StatefulSet":
            continue
        service = dep["spec"].get("serviceName")
        svc = by_kind.get("Service", {}).get(service)
        if svc is None or svc["spec"].get("clusterIP") != "None":
            problem(f"{where}: serviceName {service!r} is no headless Service here")
        host = re.sub(r"^https?://", "", str(template)).split(":")[0].split("/")[0]
        if not host.startswith(f"{{name}}.{service}."):
            problem(f"{where}: advertise {template!r} is not the pod's name under {service}")


def check_etcd_policy(by_kind: dict[str, Any]) -> None:
    """etcd's client port admits the pkwbus pods alone (no other pod takes or
    revokes a line's lease); its peer port the members alone."""
    etcd = [
        s
        for s in by_kind.get("StatefulSet", {}).values()
        if s["spec"]["template"]["metadata"]["labels"].get("app.kubernetes.io/name") == "etcd"
    ]
    if not etcd:
        return
    labels = etcd[0]["spec"]["template"]["metadata"]["labels"]
    policies = [
        p
        for p in by_kind.get("NetworkPolicy", {}).values()
        if labels_match(p["spec"]["podSelector"].get("matchLabels", {}), labels)
        and "Ingress" in p["spec"].get("policyTypes", [])
    ]
    if not policies:
        problem("StatefulSet etcd: no NetworkPolicy confines who reaches its client port")
    allowed = {"client": {"pkwbus"}, "peer": {"etcd"}}
    for p in policies:
        for rule in p["spec"].get("ingress", []):
            ports = [q.get("port") for q in rule.get("ports", [])]
            peers = rule.get("from", [])
            names = {
                f.get("podSelector", {}).get("matchLabels", {}).get("app.kubernetes.io/name")
                for f in peers
            }
            bad = (
                not ports
                or not peers
                or any(set(f) != {"podSelector"} for f in peers)
                or any(q not in allowed or not names <= allowed[str(q)] for q in ports)
            )
            if bad:
                problem(
                    f"NetworkPolicy {p['metadata']['name']}: admits {names} to ports {ports}"
                    " (client: pkwbus pods only; peer: etcd pods only)"
                )


# --- main --------------------------------------------------------------------------


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--structure", action="store_true")
    ap.add_argument("--metrics", action="store_true")
    ap.add_argument("--promql", action="store_true")
    ap.add_argument("--promtool", default="promtool")
    args = ap.parse_args()
    if not (args.structure or args.metrics or args.promql):
        ap.error("say what to check")
    try:
        if args.structure:
            check_compose()
            check_compose_standby()
            check_grafana()
            check_kubernetes()
        if args.metrics:
            check_metrics()
        if args.promql:
            check_promql(args.promtool)
    except (OSError, ValueError, KeyError, TypeError, yaml.YAMLError) as e:
        problem(f"cannot check: {type(e).__name__}: {e}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
