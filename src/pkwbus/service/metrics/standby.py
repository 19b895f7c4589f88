"""Who masters each line: ``pkwbus_line_master`` on every instance, and in hot standby
``pkwbus_standby_etcd_up`` and ``pkwbus_standby_takeovers_total``.

Made at each scrape from what the runtime holds then (interface "Hot standby"). A single
instance masters every configured line: its ``pkwbus_line_master`` is 1 for each. A
line's other series (its counters, its drives and values) come only from its master:
they leave ``/metrics`` here when the line stops (:mod:`.forget`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from pkwbus.service.runtime import Masters

__all__ = ["ETCD_UP", "LINE_MASTER", "TAKEOVERS", "MasterCollector"]

LINE_MASTER = ("pkwbus_line_master", "1 where this instance masters the line, else 0")
ETCD_UP = ("pkwbus_standby_etcd_up", "1 while this instance reaches etcd")
TAKEOVERS = ("pkwbus_standby_takeovers_total", "Times this instance took the line")


class MasterCollector(Collector):
    """``lines``: the configured lines' names now; ``masters``: who masters them (None:
    one instance, this one, masters them all)."""

    def __init__(
        self, lines: Callable[[], Sequence[str]], masters: Callable[[], Masters | None]
    ) -> None:
        self._lines = lines
        self._masters = masters

    def describe(self) -> list[Metric]:
        return []  # made at each scrape: the families depend on the mode

    def collect(self) -> Iterator[Metric]:
        masters = self._masters()
        master = GaugeMetricFamily(*LINE_MASTER, labels=["line"])
        if masters is None:
            for line in self._lines():
                master.add_metric([line], 1.0)
            yield master
            return
        lines = list(masters.lines())
        for line in lines:
            master.add_metric([line], 1.0 if masters.here(line) else 0.0)
        yield master
        yield GaugeMetricFamily(*ETCD_UP, value=1.0 if masters.etcd_up else 0.0)
        taken = CounterMetricFamily(TAKEOVERS[0].removesuffix("_total"), TAKEOVERS[1],
                                    labels=["line"])  # fmt: skip
        for line in lines:
            taken.add_metric([line], float(masters.takeovers(line)))
        yield taken
