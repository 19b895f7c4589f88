"""The dashboard, the alert rules and the interface name what the service really exports.

deploy/check compares the PromQL in deploy/ with the metric table of
interface.md; this compares both with the service's actual /metrics output:
a runtime built from a configuration polls simulated drives (one polled
parameter the drive lacks, so that the fault counter has a series too), and
``generate_latest`` of its registry is parsed for metric names and labels.
Counters that appear at their first step (errors, retries, overruns of a
healthy line) take their label names from the service's declaration.
"""

from __future__ import annotations

import asyncio
import importlib.util
import json
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, cast

import prometheus_client
import pytest
import yaml
from prometheus_client.parser import text_string_to_metric_families

from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.assembly.history import remember
from pkwbus.service.config import parse_config
from pkwbus.service.history.settings import SettingsWatcher
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.history.stream import EVENT_LABELS
from pkwbus.service.metrics.alarms import ALARM_LABELS
from pkwbus.service.metrics.devices import MISMATCH, MISMATCH_LABELS
from pkwbus.service.metrics.exposition import CounterFamily
from pkwbus.service.metrics.instrumentation import ServiceMetrics
from pkwbus.service.metrics.standby import MasterCollector
from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.profibus.line import DpSimulator
from tests.deploy.conftest import DP_DRIVES, DRIVES, service_config

ROOT = Path(__file__).resolve().parents[2]
DASHBOARDS = sorted((ROOT / "deploy" / "grafana").rglob("*.json"))
RULES = ROOT / "deploy" / "prometheus" / "rules.yml"
RULES_TEST = ROOT / "deploy" / "prometheus" / "rules_test.yml"
# Labels Prometheus adds to every scraped series.
TARGET_LABELS = {"job", "instance"}
# Series Prometheus makes itself, not the service.
PROMETHEUS_SERIES: dict[str, set[str]] = {"up": set()}
# A polled parameter the simulated drive does not have: every poll is rejected.
MISSING = "19-99"

Exported = dict[str, set[str]]  # metric name -> label names of its series


def check_deploy() -> ModuleType:
    """deploy/check_deploy.py, which holds deploy/check's copy of the interface's metric list."""
    spec = importlib.util.spec_from_file_location(
        "check_deploy", ROOT / "deploy" / "check_deploy.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def complete(text: str) -> bool:
    """Each drive has a value of 3-41 and a fault counted (series exist at 0 before)."""
    seen = {
        (sample.name, sample.labels.get("drive"))
        for family in text_string_to_metric_families(text)
        for sample in family.samples
        if sample.labels.get("parameter", "3-41") == "3-41"
        and (sample.name != "pkwbus_pkw_faults_total" or sample.value > 0)
    }
    wanted = ("pkwbus_parameter_value", "pkwbus_pkw_faults_total")
    return all((name, drive) in seen for name in wanted for drive in DRIVES)


async def scrape(folder: Path) -> str:
    """The service's /metrics text after each drive answered every poll once."""
    sim = Simulator(
        "fc", DRIVES.values(), timing=SimTiming(response_delay=0.002), catalog="danfoss-fc"
    )
    server = await sim.serve_tcp("127.0.0.1", 0)
    dp_sim = DpSimulator(DP_DRIVES.values(), dialect="danfoss-pcv", seed=3)
    dp_server = await dp_sim.serve_tcp("127.0.0.1", 0)
    extra = f'\n          - {{parameter: "{MISSING}", every: 250ms}}'
    text = service_config(server.url, folder, extra_poll=extra, dp_port=dp_server.url)
    config = parse_config(text)
    runtime = await build_runtime(config)
    history = HistoryStore(folder / "history.sqlite")  # the drives' own logs, as `pkwbus run`
    memory = remember(config, runtime, history)
    assert memory.logs is not None and memory.settings is not None
    try:
        await runtime.start()
        deadline = time.monotonic() + 20
        while True:
            text = prometheus_client.generate_latest(runtime.registry).decode()
            if complete(text) and "pkwbus_dp_diagnostics_total{" in text:
                # A drive in maintenance: the series of pkwbus_drive_maintenance.
                line, drive = next((d.line, d.name) for d in runtime.drives.values())
                runtime.runners[line].maintenance(drive, True, "a test")
                return prometheus_client.generate_latest(runtime.registry).decode()
            if time.monotonic() > deadline:
                pytest.fail(f"no values and faults from both drives after 20 s:\n{text}")
            await asyncio.sleep(0.1)
    finally:
        await runtime.stop()
        history.close()
        await server.close()
        await dp_server.close()


def exported_metrics(text: str) -> Exported:
    """Every metric name a PromQL query can use, with the label names its series carry."""
    names: Exported = {}
    for family in text_string_to_metric_families(text):
        suffixes = {
            "counter": ["_total"],
            "histogram": ["", "_bucket", "_sum", "_count"],
        }.get(family.type, [""])
        for suffix in suffixes:
            names.setdefault(family.name + suffix, set())
        for sample in family.samples:
            names.setdefault(sample.name, set()).update(sample.labels)
        if family.type == "histogram":
            names[family.name] = names[family.name + "_count"]
    return names


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Exported:
    text = asyncio.run(scrape(tmp_path_factory.mktemp("metrics")))
    names = exported_metrics(text)
    # A series without labels (the configuration's gauges, as Prometheus' own) is a series.
    unlabelled = {
        s.name for f in text_string_to_metric_families(text) for s in f.samples if not s.labels
    }
    empty = sorted(
        n
        for n, labels in names.items()
        if n.startswith("pkwbus_") and not labels and n not in unlabelled
    )
    declared = declared_counters()
    for name in empty:
        if name in declared:
            names[name] = declared[name]
    empty = [n for n in empty if n not in declared]
    assert not empty, f"no series (so no labels to check) for {empty}"
    names.update(standby_series())
    return names


class _Standby:
    """An instance in hot standby that masters line1 of two and took it once."""

    etcd_up = True

    def lines(self) -> dict[str, list[str]]:
        return {"line1": ["d1"], "line2": ["d2"]}

    def here(self, line: str) -> bool:
        return line == "line1"

    def takeovers(self, line: str) -> int:
        return int(line == "line1")


def standby_series() -> Exported:
    """The series only an instance in hot standby has (etcd, takeovers), and their labels:
    the scrape above is of a single instance."""
    registry = prometheus_client.CollectorRegistry()
    registry.register(MasterCollector(lambda: [], lambda: cast(Any, _Standby())))
    text = prometheus_client.generate_latest(registry).decode()
    found = exported_metrics(text)
    assert found["pkwbus_line_master"] == {"line"}
    return {n: labels for n, labels in found.items() if n.startswith("pkwbus_standby_")}


def declared_counters() -> Exported:
    """The counters of the service whose series come with their first step, and their labels;
    the gauge whose series come with a USS line (this scrape has FC and DP lines), and the
    gauge whose series come with a drive that contradicts its catalog."""
    metrics = ServiceMetrics(prometheus_client.CollectorRegistry())
    families = [getattr(metrics, name) for name in vars(metrics)]
    declared = {
        f"{f.name}_total": set(f.labelnames) for f in families if isinstance(f, CounterFamily)
    }
    conflict = metrics.pkw_conflict
    declared[conflict._name] = set(conflict._labelnames)
    # A series for each field a drive contradicts its catalog on: none while all agree.
    declared[MISMATCH[0]] = set(MISMATCH_LABELS)
    # A series for each active alarm or warning: none while the drives show none.
    declared["pkwbus_drive_alarm"] = set(ALARM_LABELS)
    # A series for each code of the drives' own logs, with its first entry.
    declared["pkwbus_drive_events_total"] = set(EVENT_LABELS)
    # A series for each setting that differs from its baseline, and for each drive once
    # a sweep of its settings is complete: none in a scrape this short.
    settings = SettingsWatcher(
        {}, cast(Any, None), cast(Any, None), [], prometheus_client.CollectorRegistry()
    )
    for gauge in (settings.changed, settings.swept_at):
        declared[gauge._name] = set(gauge._labelnames)
    return declared


# --- the PromQL in deploy/ ---------------------------------------------------------


@dataclass
class Query:
    where: str
    expr: str
    # Labels {{ $labels.X }} of an alert's annotations and labels.
    template_labels: set[str] = field(default_factory=set)


def dashboard_queries(path: Path) -> Iterator[Query]:
    def walk(node: Any, where: str) -> Iterator[Query]:
        if isinstance(node, dict):
            title = node.get("title") or node.get("name") or where
            if isinstance(node.get("expr"), str):
                yield Query(f"{path.name}: {title!r} {node.get('refId', '')}", node["expr"])
            if node.get("type") == "query":  # a templating variable
                q = node.get("query")
                q = q.get("query") if isinstance(q, dict) else q
                if isinstance(q, str):
                    yield Query(f"{path.name}: variable {node.get('name')}", q)
            for key, value in node.items():
                if key not in ("expr", "query"):
                    yield from walk(value, title)
        elif isinstance(node, list):
            for item in node:
                yield from walk(item, where)

    yield from walk(json.loads(path.read_text()), "")


def rule_queries() -> Iterator[Query]:
    for group in yaml.safe_load(RULES.read_text())["groups"]:
        for rule in group["rules"]:
            texts = [*rule.get("labels", {}).values(), *rule.get("annotations", {}).values()]
            used = {m for t in texts for m in re.findall(r"\$labels\.(\w+)", str(t))}
            name = rule.get("alert") or rule.get("record")
            yield Query(f"{RULES.name}: {name}", str(rule["expr"]), used)


ALL_QUERIES = [q for p in DASHBOARDS for q in dashboard_queries(p)] + list(rule_queries())

KEYWORDS = {"and", "or", "unless", "bool", "offset", "inf", "nan"}
SELECTOR = re.compile(r"([a-zA-Z_:][\w:]*)?\s*\{([^}]*)\}")
MATCHER = re.compile(r'(\w+)\s*(?:=~|!~|!=|=)\s*"(?:[^"\\]|\\.)*"')
GROUPING = re.compile(r"\b(by|without|on|ignoring|group_left|group_right)\s*\(([^)]*)\)")
LABEL_VALUES = re.compile(r"label_values\((.*),\s*(\w+)\s*\)", re.S)


@dataclass
class Parsed:
    metrics: list[str] = field(default_factory=list)
    matchers: list[tuple[str, set[str]]] = field(default_factory=list)  # (metric, labels)
    grouping: list[tuple[str, set[str]]] = field(default_factory=list)  # (keyword, labels)


def parse_promql(expr: str) -> Parsed:
    """Metric names, label matchers and grouping labels of a PromQL expression.

    Not a PromQL parser (promtool checks the syntax in deploy/check): enough
    for the expressions of a dashboard and of alert rules.
    """
    out = Parsed()
    m = LABEL_VALUES.fullmatch(expr.strip())
    if m:  # Grafana's label_values(SELECTOR, LABEL): LABEL must be on the series
        inner = parse_promql(m.group(1))
        out.metrics += inner.metrics
        out.matchers += inner.matchers
        out.grouping += [*inner.grouping, ("label_values", {m.group(2)})]
        return out
    text = re.sub(r"\[[^\]]*\]", "", expr)  # ranges, with Grafana's $__rate_interval

    def selector(s: re.Match[str]) -> str:
        labels = set(MATCHER.findall(s.group(2)))
        out.matchers.append((s.group(1) or "", labels))
        return f" {s.group(1) or ''} "

    text = SELECTOR.sub(selector, text)

    def grouping(g: re.Match[str]) -> str:
        out.grouping.append((g.group(1), {x.strip() for x in g.group(2).split(",") if x.strip()}))
        return " "

    text = GROUPING.sub(grouping, text)
    text = re.sub(r'"(?:[^"\\]|\\.)*"', " ", text)
    text = re.sub(r"\$\{?\w+\}?", " ", text)  # Grafana variables
    for ident in re.finditer(r"[a-zA-Z_:][\w:]*(?=(\s*\()?)", text):
        word = ident.group(0)
        if ident.group(1) or word.lower() in KEYWORDS:
            continue  # a function or aggregation, or an operator
        if text[ident.start() - 1 : ident.start()].isdigit():
            continue  # the unit of 5m, the exponent of 1e3
        out.metrics.append(word)
    return out


def labels_of(name: str, exported: Exported) -> set[str] | None:
    if name in PROMETHEUS_SERIES:
        return PROMETHEUS_SERIES[name] | TARGET_LABELS
    if name in exported:
        return exported[name] | TARGET_LABELS
    return None


def test_parse_promql_finds_names_matchers_and_grouping() -> None:
    p = parse_promql(
        "histogram_quantile(0.9, sum by (line, le)"
        ' (rate(a_bucket{x=~"$v", y="1"}[$__rate_interval])))'
        " / on (line) group_left () b unless time() - c offset 5m > 1e3 or vector(0)"
    )
    assert p.metrics == ["a_bucket", "b", "c"]
    assert p.matchers == [("a_bucket", {"x", "y"})]
    assert p.grouping == [("by", {"line", "le"}), ("on", {"line"}), ("group_left", set())]
    v = parse_promql('label_values(m{instance=~"$instance"}, line)')
    assert (v.metrics, v.grouping) == (["m"], [("label_values", {"line"})])


def test_deploy_has_queries() -> None:
    assert DASHBOARDS, "no dashboard under deploy/grafana"
    assert sum(1 for q in ALL_QUERIES if q.where.startswith(RULES.name)) >= 5
    assert sum(1 for q in ALL_QUERIES if not q.where.startswith(RULES.name)) >= 10


@pytest.mark.parametrize("query", ALL_QUERIES, ids=lambda q: q.where)
def test_query_names_only_exported_metrics_and_labels(query: Query, exported: Exported) -> None:
    parsed = parse_promql(query.expr)
    assert parsed.metrics, f"no metric found in {query.expr!r}"
    problems = []
    for name in parsed.metrics:
        if labels_of(name, exported) is None:
            problems.append(f"{name} is not exported by the service")
    for name, labels in parsed.matchers:
        known = labels_of(name, exported)
        if known is not None and labels - known:
            problems.append(
                f"{name} has no label {sorted(labels - known)} (it has {sorted(known)})"
            )
    for keyword, labels in parsed.grouping:
        if keyword in ("without", "ignoring"):
            continue  # a label that is not there changes nothing
        for name in parsed.metrics:
            known = labels_of(name, exported)
            if known is not None and labels - known:
                problems.append(f"{keyword} {sorted(labels - known)}: not a label of {name}")
    if query.template_labels:
        known = set().union(*(labels_of(n, exported) or set() for n in parsed.metrics))
        if query.template_labels - known:
            missing = ", ".join(f"$labels.{x}" for x in sorted(query.template_labels - known))
            problems.append(f"{missing} in the alert's text: no such label on its series")
    assert not problems, f"{query.where}: {query.expr!r}:\n  " + "\n  ".join(problems)


def test_rule_tests_use_exported_series(exported: Exported) -> None:
    """The input series of rules_test.yml carry the labels the service's series do."""
    problems = []
    for i, test in enumerate(yaml.safe_load(RULES_TEST.read_text())["tests"]):
        for series in test.get("input_series", []):
            m = SELECTOR.fullmatch(series["series"].strip())
            assert m, series["series"]
            name, labels = m.group(1), set(MATCHER.findall(m.group(2)))
            known = labels_of(name, exported)
            if known is None:
                problems.append(f"tests[{i}]: {name} is not exported")
            elif labels != known:
                problems.append(f"tests[{i}]: {name} labels {sorted(labels)} != {sorted(known)}")
    assert not problems, "\n".join(sorted(set(problems)))


# --- the interface -----------------------------------------------------------------


def interface_list(monkeypatch: pytest.MonkeyPatch) -> tuple[set[str], str]:
    module = check_deploy()
    monkeypatch.chdir(ROOT)  # check_deploy looks for ../shared/design/interface.md from here
    names, source = module.interface_metrics()
    return set(names), source


def test_interface_metrics_are_exported(
    exported: Exported, monkeypatch: pytest.MonkeyPatch
) -> None:
    names, source = interface_list(monkeypatch)
    assert len(names) >= 15
    later = check_deploy().NOT_YET_EXPORTED
    readme = (ROOT / "README.md").read_text()
    assert all(f"`{n}` is not exported yet" in readme for n in later), "README.md: say so"
    assert not later & set(exported), "exported now: out of NOT_YET_EXPORTED and README.md"
    missing = sorted(names - set(exported) - later)
    assert not missing, f"in the interface ({source}) but not exported: {missing}"


def test_service_exports_only_interface_metrics(
    exported: Exported, monkeypatch: pytest.MonkeyPatch
) -> None:
    names, source = interface_list(monkeypatch)
    histograms = {n for n in names for s in ("_bucket", "_sum", "_count") if n + s in exported}
    allowed = names | {n + s for n in histograms for s in ("_bucket", "_sum", "_count")}
    beyond = check_deploy().BEYOND_INTERFACE  # documented in README.md: deploy/check says so
    readme = (ROOT / "README.md").read_text()
    assert all(f"`{n}" in readme for n in beyond), "README.md: document them"
    allowed |= beyond
    extra = sorted(n for n in exported if n.startswith("pkwbus_") and n not in allowed)
    assert not extra, f"exported but not in the interface ({source}): {extra}"


def test_check_deploy_copy_matches_interface_md(monkeypatch: pytest.MonkeyPatch) -> None:
    module = check_deploy()
    monkeypatch.chdir(ROOT)
    path = module.interface_md()
    if path is None:
        pytest.skip("interface.md not beside the repository (CI): only the built-in copy is used")
    names, _ = module.interface_metrics()
    assert set(module.FALLBACK_METRICS) == set(names), (
        f"deploy/check_deploy.py FALLBACK_METRICS differs from {path}"
    )
