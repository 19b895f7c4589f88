"""Prometheus metrics with exactly the names and labels of interface.md.

Device values (parameter values, drive and line state, status words) come
from a custom Collector built from a copy of the snapshot at each scrape, so
a scrape never causes bus traffic and values that disappear also disappear
from the output. The service's own counters are ordinary Counters and a
Histogram, their label values initialised from the configuration (see
:class:`LineMetrics`).
"""

from __future__ import annotations

import platform
import weakref
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from prometheus_client.core import GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from pkwbus import __version__
from pkwbus.master.jobs import Cancelled, JobKind, JobOutcome, JobResult
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.transaction import (
    Answered,
    ErrorKind,
    ExchangeResult,
    Failure,
    Outcome,
    Rejected,
    Reply,
)
from pkwbus.protocol import pkw
from pkwbus.protocol.dialects import Dialect
from pkwbus.protocol.pzd import STATUS_BITS, Profile

ERROR_KINDS = [k.value for k in ErrorKind if k is not ErrorKind.PORT]
DURATION_BUCKETS = (0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5, 1.0, 2.0)


@dataclass(frozen=True)
class ParameterInfo:
    """What ``pkwbus_parameter_info`` says of one polled parameter."""

    line: str
    drive: str
    parameter: str
    index: int
    pnu: int
    name: str
    unit: str
    type: str


@dataclass(frozen=True)
class DriveInfo:
    line: str
    profile: Profile


_LABEL_OF_TYPE: dict[type[Outcome], JobOutcome] = {
    Answered: JobOutcome.OK,
    Rejected: JobOutcome.REJECTED,
    Cancelled: JobOutcome.CANCELLED,
}


def fault_labels(fault: int | None, short: str) -> tuple[str, str]:
    """The ``fault_code`` and ``fault`` labels of ``pkwbus_pkw_faults_total``."""
    return ("" if fault is None else str(fault), short)


def outcome_label(outcome: Outcome) -> JobOutcome:
    label = _LABEL_OF_TYPE.get(type(outcome))
    if label is not None:
        return label
    if isinstance(outcome, Answered):
        return JobOutcome.OK
    if isinstance(outcome, Rejected):
        return JobOutcome.REJECTED
    if isinstance(outcome, Cancelled):
        return JobOutcome.CANCELLED
    return JobOutcome.TIMEOUT


class SnapshotCollector(Collector):
    """Builds the device-value families from a copy of the snapshot."""

    def __init__(
        self,
        snapshot: Snapshot,
        drives: Mapping[str, DriveInfo],
        parameters: Iterable[ParameterInfo],
    ) -> None:
        self._snapshot = snapshot
        self._drives = dict(drives)
        self._parameters = list(parameters)
        self._line_of = {p.drive: p.line for p in self._parameters}
        self._line_of.update({name: d.line for name, d in self._drives.items()})

    def describe(self) -> list[Metric]:
        return list(self._families(Snapshot()))

    def collect(self) -> Iterator[Metric]:
        return self._families(self._snapshot.copy())

    def _families(self, snap: Snapshot) -> Iterator[Metric]:
        pv = ("line", "drive", "parameter", "index")
        value = GaugeMetricFamily(
            "pkwbus_parameter_value", "Latest value read from the drive, scaled", labels=pv
        )
        stamp = GaugeMetricFamily(
            "pkwbus_parameter_last_update_timestamp_seconds",
            "When the value was read (Unix time)",
            labels=pv,
        )
        for (drive, parameter, index), reading in snap.readings.items():
            if isinstance(reading.value, str):
                continue  # text values appear in the API, not as numbers
            labels = [self._line_of.get(drive, ""), drive, parameter, str(index)]
            value.add_metric(labels, float(reading.value))
            stamp.add_metric(labels, reading.timestamp)
        yield value
        yield stamp
        yield self._info()
        yield from self._drive_families(snap)
        line_up = GaugeMetricFamily("pkwbus_line_up", "1 while the port is open", labels=["line"])
        for line, up in snap.lines.items():
            line_up.add_metric([line], 1.0 if up else 0.0)
        yield line_up

    def _info(self) -> GaugeMetricFamily:
        info = GaugeMetricFamily(
            "pkwbus_parameter_info",
            "PNU, name, unit and type of each polled parameter",
            labels=["line", "drive", "parameter", "index", "pnu", "name", "unit", "type"],
        )
        for p in self._parameters:
            labels = [
                p.line,
                p.drive,
                p.parameter,
                str(p.index),
                str(p.pnu),
                p.name,
                p.unit,
                p.type,
            ]
            info.add_metric(labels, 1.0)
        return info

    def _drive_families(self, snap: Snapshot) -> Iterator[Metric]:
        up = GaugeMetricFamily(
            "pkwbus_drive_up", "1 while the drive answers, else 0", labels=["line", "drive"]
        )
        word = GaugeMetricFamily(
            "pkwbus_drive_status_word", "Last raw status word", labels=["line", "drive"]
        )
        bits = GaugeMetricFamily(
            "pkwbus_drive_status_bit",
            "Each named bit of the last status word",
            labels=["line", "drive", "bit"],
        )
        for drive, state in snap.drives.items():
            info = self._drives.get(drive)
            line = info.line if info else self._line_of.get(drive, "")
            up.add_metric([line, drive], 1.0 if state.up else 0.0)
            if state.status_word is None or info is None:
                continue
            word.add_metric([line, drive], float(state.status_word))
            for bit, name in STATUS_BITS[info.profile].items():
                bits.add_metric([line, drive, name], float(state.status_word >> bit & 1))
        yield up
        yield word
        yield bits


class ServiceMetrics:
    """The service's own counters; one :class:`LineMetrics` per line feeds them."""

    def __init__(self, registry: CollectorRegistry) -> None:
        ld = ["line", "drive"]
        self.faults = Counter(
            "pkwbus_pkw_faults",
            "Drive rejections by fault number and text",
            [*ld, "fault_code", "fault"],
            registry=registry,
        )
        self.errors = Counter(
            "pkwbus_telegram_errors",
            "Exchanges without a usable answer, by kind",
            [*ld, "kind"],
            registry=registry,
        )
        self.telegrams = Counter(
            "pkwbus_telegrams", "Telegram exchanges attempted", ld, registry=registry
        )
        self.jobs = Counter(
            "pkwbus_jobs",
            "Finished jobs by kind and outcome",
            [*ld, "kind", "outcome"],
            registry=registry,
        )
        self.retries = Counter(
            "pkwbus_job_retries",
            "Telegrams repeated because an answer was missing, bad or not yet there",
            ld,
            registry=registry,
        )
        self.duration = Histogram(
            "pkwbus_transaction_duration_seconds",
            "Request start to valid response",
            ["line"],
            buckets=DURATION_BUCKETS,
            registry=registry,
        )
        self.busy = Counter(
            "pkwbus_line_busy_seconds",
            "Time the line carried a transaction (rate() = utilisation)",
            ["line"],
            registry=registry,
        )
        self.overruns = Counter(
            "pkwbus_poll_overruns",
            "Polls that started later than one interval after due",
            ld,
            registry=registry,
        )
        build = Gauge(
            "pkwbus_build_info", "pkwbus and Python versions", ["version", "python"],
            registry=registry,
        )  # fmt: skip
        build.labels(__version__, platform.python_version()).set(1)
        # PROFIBUS DP slaves: the families are there from the start; their series
        # come with the DP lines of a configuration.
        self.dp_state = Gauge(
            "pkwbus_dp_slave_state",
            "PROFIBUS DP: 1 for the slave's current state",
            [*ld, "state"],
            registry=registry,
        )
        self.dp_restarts = Counter(
            "pkwbus_dp_restarts",
            "PROFIBUS DP: times a slave had to be parametrised again, by reason",
            [*ld, "reason"],
            registry=registry,
        )
        self.dp_diagnostics = Counter(
            "pkwbus_dp_diagnostics",
            "PROFIBUS DP: diagnosis flags seen, by flag",
            [*ld, "flag"],
            registry=registry,
        )

    def for_line(self, line: str, drives: Mapping[str, Dialect]) -> LineMetrics:
        """The counters of ``line``; ``drives`` maps each configured drive to its dialect."""
        return LineMetrics(self, line, drives)


class LineMetrics:
    """The scheduler's events for one line, turned into counter increments.

    A labelled counter has no series until its first increment, and
    ``increase()``/``rate()`` cannot see that first step (no earlier sample),
    so the Prometheus guidance is to create every label set known in advance
    at 0 ("Avoid missing metrics", Prometheus instrumentation practices).
    Created here, for each configured drive of the line:

    - ``pkwbus_pkw_faults_total``: every fault number of the drive's dialect
      table with its short text, and "no change rights" where the dialect
      has that answer (alert ``PkwbusDriveFaults``, dashboard fault panel).
      A number outside the table, or a drive not in the configuration, still
      appears only at its first fault;
    - ``pkwbus_telegram_errors_total``: every ``kind`` but ``port`` (a port
      failure puts nothing on the wire and is not counted) (alert
      ``PkwbusTelegramErrorRateRising``, dashboard error panels);
    - ``pkwbus_jobs_total``: ``kind`` read/write times every ``outcome``
      (dashboard outcome panel);
    - ``pkwbus_telegrams_total``, ``pkwbus_job_retries_total``,
      ``pkwbus_poll_overruns_total`` per drive, ``pkwbus_line_busy_seconds_total``
      and ``pkwbus_transaction_duration_seconds`` per line.

    The PROFIBUS DP counters of the interface (restarts by ``reason``,
    diagnostics by ``flag``) have their labels known in advance too: created
    the same way once they exist.
    """

    def __init__(self, m: ServiceMetrics, line: str, drives: Mapping[str, Dialect]) -> None:
        self._m = m
        self._line = line
        self._faults = {
            (d, *labels): m.faults.labels(line, d, *labels)
            for d, dialect in drives.items()
            for labels in (fault_labels(n, short) for n, short in pkw.rejections(dialect))
        }
        self._busy = m.busy.labels(line)
        self._duration = m.duration.labels(line)
        self._telegrams = {d: m.telegrams.labels(line, d) for d in drives}
        self._retries = {d: m.retries.labels(line, d) for d in drives}
        self._overruns = {d: m.overruns.labels(line, d) for d in drives}
        self._errors = {(d, k): m.errors.labels(line, d, k) for d in drives for k in ERROR_KINDS}
        self._jobs = {
            (d, kind, outcome): m.jobs.labels(line, d, kind, outcome.value)
            for d in drives
            for kind in ("read", "write")
            for outcome in JobOutcome
        }

    def exchange(self, drive: str, result: ExchangeResult, busy: float) -> None:
        if isinstance(result, Failure) and result.kind is ErrorKind.PORT:
            return  # nothing went on the wire
        self._telegrams[drive].inc()
        self._busy.inc(busy)
        if isinstance(result, Reply):
            self._duration.observe(result.duration)
        else:
            self._errors[(drive, result.kind.value)].inc()

    def job_finished(self, drive: str, kind: JobKind, result: JobResult) -> None:
        outcome = result.outcome
        key = (drive, kind.value, outcome_label(outcome))
        child = self._jobs.get(key)
        if child is None:
            child = self._jobs[key] = self._m.jobs.labels(self._line, drive, key[1], key[2].value)
        child.inc()
        tally = result.tally
        if tally is not None:
            if tally.retries:
                self._retries[drive].inc(tally.retries)
            unexpected = tally.errors.get(ErrorKind.UNEXPECTED, 0)
            if unexpected:
                self._errors[(drive, ErrorKind.UNEXPECTED.value)].inc(unexpected)
        if isinstance(outcome, Rejected):
            labels = fault_labels(outcome.fault, outcome.short)
            fault = self._faults.get((drive, *labels))
            if fault is None:
                fault = self._m.faults.labels(self._line, drive, *labels)
            fault.inc()

    def overrun(self, drive: str) -> None:
        self._overruns[drive].inc()


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
