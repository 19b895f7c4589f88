"""Series that leave ``/metrics`` with what they describe: a line or a drive a reload took
away. A scrape after it shows none of them (Prometheus marks them stale)."""

from __future__ import annotations

import contextlib

from prometheus_client import CollectorRegistry
from prometheus_client.metrics import MetricWrapperBase

from pkwbus.service.metrics.exposition import CounterFamily, MetricsRegistry

__all__ = ["forget_series"]


def forget_series(registry: CollectorRegistry, **labels: str) -> None:
    """Remove every series whose labels include all of ``labels`` (``line=``, ``drive=``)
    from the registry's labelled families."""
    if not isinstance(registry, MetricsRegistry):
        return
    for collector in registry.collectors():
        if isinstance(collector, CounterFamily):
            collector.forget(labels)
        elif isinstance(collector, MetricWrapperBase):
            with contextlib.suppress(ValueError):  # a family without one of these labels
                collector.remove_by_labels(labels)
