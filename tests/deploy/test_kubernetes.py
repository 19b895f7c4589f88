"""The Kubernetes manifests and the compose file: what holds them together.

deploy/image-check renders and runs them (kubectl kustomize, CRD schemas,
podman kube play, podman-compose); these read the files.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[2]
K8S = ROOT / "deploy" / "kubernetes"
RULES = ROOT / "deploy" / "prometheus" / "rules.yml"
COMPOSE = ROOT / "deploy" / "compose.yaml"


def kustomization() -> dict[str, Any]:
    return dict(yaml.safe_load((K8S / "kustomization.yaml").read_text()))


def objects() -> list[dict[str, Any]]:
    docs: list[dict[str, Any]] = []
    for res in kustomization()["resources"]:
        docs += [d for d in yaml.safe_load_all((K8S / res).read_text()) if d]
    return docs


def of_kind(kind: str) -> list[dict[str, Any]]:
    return [d for d in objects() if d["kind"] == kind]


def named(d: dict[str, Any]) -> str | None:
    """The app.kubernetes.io/name of a workload's pods (or of a policy's selected pods)."""
    spec = d["spec"]
    labels = spec["template"]["metadata"]["labels"] if "template" in spec else {}
    if "podSelector" in spec:
        labels = spec["podSelector"]["matchLabels"]
    return labels.get("app.kubernetes.io/name")


def pkwbus_workloads() -> list[dict[str, Any]]:
    """pkwbus's Deployments and StatefulSets (a hot standby group); not etcd's."""
    return [d for d in of_kind("Deployment") + of_kind("StatefulSet") if named(d) == "pkwbus"]


def test_the_prometheus_rule_carries_the_alert_rules_as_they_are() -> None:
    (rule,) = of_kind("PrometheusRule")
    assert rule["spec"]["groups"] == yaml.safe_load(RULES.read_text())["groups"]


def test_each_gateway_config_comes_from_a_generator_so_a_change_rolls_the_pod() -> None:
    generators = {g["name"]: g for g in kustomization()["configMapGenerator"]}
    deployments = pkwbus_workloads()
    assert of_kind("Deployment") and len(deployments) > len(of_kind("Deployment"))
    for dep in deployments:
        pod = dep["spec"]["template"]["spec"]
        names = [v["configMap"]["name"] for v in pod["volumes"] if "configMap" in v]
        assert names, dep["metadata"]["name"]
        for name in names:
            assert name in generators, f"{name} is not generated: a change would not roll the pod"
            for spec in generators[name]["files"]:
                key, _, src = spec.rpartition("=")
                assert key == "config.yaml"
                config = yaml.safe_load((K8S / src).read_text())
                assert config["listen"] == "0.0.0.0:9725"
    # No ConfigMap written out by hand beside the generated ones.
    assert not of_kind("ConfigMap")


def test_the_network_policy_admits_only_prometheus_and_write_clients_to_the_api() -> None:
    (policy,) = [p for p in of_kind("NetworkPolicy") if named(p) == "pkwbus"]
    spec = policy["spec"]
    selected = spec["podSelector"]["matchLabels"]
    for dep in pkwbus_workloads():
        labels = dep["spec"]["template"]["metadata"]["labels"]
        assert selected.items() <= labels.items(), dep["metadata"]["name"]
    assert "Ingress" in spec["policyTypes"]
    (rule,) = spec["ingress"]
    assert rule["ports"] == [{"port": "http", "protocol": "TCP"}]
    peers = rule["from"]
    assert len(peers) == 2
    prometheus = next(p for p in peers if "namespaceSelector" in p)
    assert prometheus["podSelector"]["matchLabels"] == {"app.kubernetes.io/name": "prometheus"}
    writers = next(p for p in peers if "namespaceSelector" not in p)
    assert writers["podSelector"]["matchLabels"] == {"pkwbus.plant.example/write-client": "true"}


def test_etcd_admits_only_pkwbus_pods_to_its_client_port() -> None:
    """No other pod can take or revoke a line's lease; the members talk on the peer port."""
    policies = [p for p in of_kind("NetworkPolicy") if named(p) == "etcd"]
    (policy,) = policies
    assert policy["spec"]["policyTypes"] == ["Ingress"]
    admitted: dict[str, list[Any]] = {}
    for rule in policy["spec"]["ingress"]:
        for port in rule["ports"]:
            admitted.setdefault(port["port"], []).extend(rule["from"])
    assert set(admitted) == {"client", "peer"}
    only = {"podSelector": {"matchLabels": {"app.kubernetes.io/name": "pkwbus"}}}
    assert admitted["client"] == [only]
    assert admitted["peer"] == [
        {"podSelector": {"matchLabels": {"app.kubernetes.io/name": "etcd"}}}
    ]
    (etcd,) = [s for s in of_kind("StatefulSet") if named(s) == "etcd"]
    ports = {
        p["name"]: p["containerPort"]
        for p in etcd["spec"]["template"]["spec"]["containers"][0]["ports"]
    }
    assert (ports["client"], ports["peer"]) == (2379, 2380)
    # The pkwbus pods' own policy lets them out to that port.
    (api,) = [p for p in of_kind("NetworkPolicy") if named(p) == "pkwbus"]
    out = [r for r in api["spec"]["egress"] if r.get("to")]
    assert any(r["ports"] == [{"port": 2379, "protocol": "TCP"}] for r in out)


def test_the_standby_group_keeps_each_pods_audit_db_and_advertises_each_pod() -> None:
    (group,) = [d for d in of_kind("StatefulSet") if named(d) == "pkwbus"]
    spec = group["spec"]
    (claim,) = spec["volumeClaimTemplates"]
    pod = spec["template"]["spec"]
    (container,) = pod["containers"]
    mounts = {m["mountPath"]: m["name"] for m in container["volumeMounts"]}
    config = yaml.safe_load((K8S / "config" / "standby-1.yaml").read_text())
    audit = Path(config["audit_db"])
    assert mounts[str(audit.parent)] == claim["metadata"]["name"]
    assert claim["metadata"]["name"] not in {v["name"] for v in pod["volumes"]}  # no emptyDir
    # One DNS name per pod under the headless Service; PKWBUS_ADVERTISE names it.
    (service,) = [s for s in of_kind("Service") if s["metadata"]["name"] == spec["serviceName"]]
    assert service["spec"]["clusterIP"] == "None"
    assert service["spec"]["selector"].items() <= spec["template"]["metadata"]["labels"].items()
    env = {e["name"]: e for e in container["env"]}
    advertise = env["PKWBUS_ADVERTISE"]["value"]
    namespace = group["metadata"]["namespace"]
    assert advertise == f"http://{{name}}.{spec['serviceName']}.{namespace}.svc:9725"
    assert env["PKWBUS_INSTANCE"]["valueFrom"]["fieldRef"]["fieldPath"] == "metadata.name"
    budgets = [b for b in of_kind("PodDisruptionBudget") if named_budget(b) == "standby-1"]
    assert [b["spec"]["minAvailable"] for b in budgets] == [1]
    probes = {"startupProbe", "livenessProbe", "readinessProbe"}
    assert probes <= container.keys()


def named_budget(budget: dict[str, Any]) -> str | None:
    return budget["spec"]["selector"]["matchLabels"].get("app.kubernetes.io/instance")


def test_compose_publishes_on_loopback_only() -> None:
    compose = yaml.safe_load(COMPOSE.read_text())
    for name, service in compose["services"].items():
        for port in service.get("ports", []):
            assert str(port).startswith("127.0.0.1:"), f"{name}: {port}"
