"""The checks that need no container: the dashboard JSON against grafana-foundation-sdk,
the compose file against the compose-spec schema, the Kubernetes manifests rendered by
kubectl kustomize against the prometheus-operator CRDs."""

from __future__ import annotations

import json
import re
from typing import Any

import yaml

from .processes import run
from .prometheus import panels
from .report import expect, say, step
from .settings import COMPOSE, COMPOSE_STANDBY, DASHBOARD, K8S, RULES, SCHEMAS

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
    with step("compose files valid against the compose-spec schema"):
        v = validator(json.loads((SCHEMAS / "compose-spec.json").read_text()))
        for path in (COMPOSE, COMPOSE_STANDBY):
            compose = yaml.safe_load(path.read_text())
            errors = schema_errors(v, compose)
            expect(not errors, f"{path}:\n  " + "\n  ".join(errors))
            damaged = json.loads(json.dumps(compose))
            next(iter(damaged["services"].values()))["read_onyl"] = True
            expect(bool(schema_errors(v, damaged)), "the schema does not catch a misspelt key")
            say(f"    {path}: valid; a misspelt key in a copy is caught")
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
