"""``pkwbus_drive_maintenance``: the drives in maintenance, with their reason, from the
snapshot (a series while a drive is in maintenance, none otherwise)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from prometheus_client.core import GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from pkwbus.master.snapshot import Snapshot

__all__ = ["MAINTENANCE", "MaintenanceCollector"]

MAINTENANCE = (
    "pkwbus_drive_maintenance",
    "1 while the drive is in maintenance: nothing goes out to it, and it is neither up nor"
    " down (reason as given)",
)


class MaintenanceCollector(Collector):
    def __init__(self, snapshot: Snapshot, line_of: Mapping[str, str]) -> None:
        self._snapshot = snapshot
        self._line_of = line_of

    def collect(self) -> Iterator[Metric]:
        family = GaugeMetricFamily(*MAINTENANCE, labels=["line", "drive", "reason"])
        for drive, held in list(self._snapshot.maintenance.items()):
            family.add_metric([self._line_of.get(drive, ""), drive, held.reason], 1.0)
        yield family

    def describe(self) -> Iterator[Metric]:
        yield GaugeMetricFamily(*MAINTENANCE, labels=["line", "drive", "reason"])
