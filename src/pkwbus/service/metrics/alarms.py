"""``pkwbus_drive_alarm{line,drive,code,text,kind}``: the drives' active alarms and warnings,
from the snapshot (:attr:`pkwbus.master.snapshot.Snapshot.alarms`, kept by its writer as the
polled alarm words and fault numbers tell them: :mod:`pkwbus.master.alarms`). A series is 1
while its alarm is active; there is none otherwise."""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from prometheus_client.core import GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from pkwbus.master.snapshot import Snapshot

__all__ = ["ALARM", "ALARM_LABELS", "AlarmCollector"]

ALARM_LABELS = ("line", "drive", "code", "text", "kind")
ALARM = (
    "pkwbus_drive_alarm",
    "1 while the drive shows this alarm or warning (code and text from the vendor's"
    " table; no series when none is active)",
)


class AlarmCollector(Collector):
    def __init__(self, snapshot: Snapshot, line_of: Mapping[str, str]) -> None:
        self._snapshot = snapshot
        self._line_of = line_of

    def collect(self) -> Iterator[Metric]:
        family = GaugeMetricFamily(*ALARM, labels=list(ALARM_LABELS))
        for drive, active in list(self._snapshot.alarms.items()):
            line = self._line_of.get(drive, "")
            for shown in active:
                alarm = shown.alarm
                family.add_metric([line, drive, alarm.code, alarm.text, alarm.kind], 1.0)
        yield family

    def describe(self) -> Iterator[Metric]:
        yield GaugeMetricFamily(*ALARM, labels=list(ALARM_LABELS))
