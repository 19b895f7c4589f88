"""The service's own gauges and counters beside the lines': the HTTP API's (audit stores
that failed, refused requests) and the configuration's (its last reload)."""

from __future__ import annotations

import time
import weakref

from prometheus_client import CollectorRegistry, Counter, Gauge

__all__ = ["AUDIT_STAGES", "REFUSAL_REASONS", "ApiMetrics", "ConfigMetrics", "api_metrics"]

AUDIT_STAGES = ("attempt", "outcome", "refusals")
REFUSAL_REASONS = ("unauthenticated", "forbidden", "writes_disabled")


class ApiMetrics:
    """The HTTP API's counters: audit stores that failed, requests refused for want of
    a valid token. Every label value starts at zero, so an alert sees the series."""

    def __init__(self, registry: CollectorRegistry) -> None:
        self.audit_errors = Counter(
            "pkwbus_audit_errors",
            "Audit log stores that failed, by stage: attempt (the write was refused,"
            " nothing sent), outcome (the row stays pending), refusals (the tally)",
            ["stage"],
            registry=registry,
        )
        self.refusals = Counter(
            "pkwbus_api_refusals",
            "API requests refused for want of a valid token, by reason",
            ["reason"],
            registry=registry,
        )
        for stage in AUDIT_STAGES:
            self.audit_errors.labels(stage)
        for reason in REFUSAL_REASONS:
            self.refusals.labels(reason)


_API_METRICS: weakref.WeakKeyDictionary[CollectorRegistry, ApiMetrics] = weakref.WeakKeyDictionary()


def api_metrics(registry: CollectorRegistry) -> ApiMetrics:
    """The registry's API counters, made on first use (a registry takes a name once)."""
    metrics = _API_METRICS.get(registry)
    if metrics is None:
        metrics = _API_METRICS[registry] = ApiMetrics(registry)
    return metrics


class ConfigMetrics:
    """Whether the running configuration is the file's (``pkwbus_config_last_reload_*``,
    named as Prometheus names its own): 1 and the time it was loaded at the start and after
    each reload that loaded the file; 0 after one that did not (the file has a problem),
    until a good one is loaded."""

    def __init__(self, registry: CollectorRegistry) -> None:
        self.successful = Gauge(
            "pkwbus_config_last_reload_successful",
            "1 when the last reload (or the start) loaded the configuration file, else 0",
            registry=registry,
        )
        self.loaded_at = Gauge(
            "pkwbus_config_last_reload_success_timestamp_seconds",
            "When the running configuration was loaded (the start, or the last reload that"
            " loaded the file)",
            registry=registry,
        )
        self.loaded()

    def loaded(self) -> None:
        self.successful.set(1)
        self.loaded_at.set(time.time())

    def failed(self) -> None:
        self.successful.set(0)
