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


def test_the_prometheus_rule_carries_the_alert_rules_as_they_are() -> None:
    (rule,) = of_kind("PrometheusRule")
    assert rule["spec"]["groups"] == yaml.safe_load(RULES.read_text())["groups"]


def test_each_gateway_config_comes_from_a_generator_so_a_change_rolls_the_pod() -> None:
    generators = {g["name"]: g for g in kustomization()["configMapGenerator"]}
    deployments = of_kind("Deployment")
    assert deployments
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
    (policy,) = of_kind("NetworkPolicy")
    spec = policy["spec"]
    selected = spec["podSelector"]["matchLabels"]
    for dep in of_kind("Deployment"):
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


def test_compose_publishes_on_loopback_only() -> None:
    compose = yaml.safe_load(COMPOSE.read_text())
    for name, service in compose["services"].items():
        for port in service.get("ports", []):
            assert str(port).startswith("127.0.0.1:"), f"{name}: {port}"
