"""Prometheus on this machine scraping the container: the dashboard's queries as Grafana
sends them, and the alert rules as they are."""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import time
import urllib.parse
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml

from .processes import free_port, http, on_exit, wait_until
from .report import CheckFailed, expect, say
from .settings import DASHBOARD, DATASOURCE, RULES


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


# --- Grafana's intervals ------------------------------------------------------------------


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


# --- the checks ---------------------------------------------------------------------------


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
            for k, seconds in (
                ("__rate_interval", rate_interval),
                ("__interval", interval),
                ("__range", span),
            ):
                expr = expr.replace(f"${{{k}}}", fmt_s(seconds)).replace(f"${k}", fmt_s(seconds))
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
