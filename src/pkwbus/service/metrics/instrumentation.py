"""The service's own metrics (its instrumentation), with exactly the names and labels
the README documents: exchanges, faults, jobs, line time and overruns per line
and DP slave states (:class:`LineMetrics`, an observer of the line's stream of events),
the audit log's and the API's refusals (:class:`ApiMetrics`).

Device values (parameter values, drive and line state, status words) are not here:
they come from :class:`~pkwbus.service.metrics.devices.SnapshotCollector`, built from
a copy of the snapshot at each scrape. The counters are
:class:`~pkwbus.service.metrics.exposition.CounterFamily` series that keep their
rendered line (see :mod:`pkwbus.service.metrics.exposition`), plus a Histogram; which
label values exist at 0 from the start is said at :class:`LineMetrics`.
"""

from __future__ import annotations

import platform
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from prometheus_client import CollectorRegistry, Gauge, Histogram

from pkwbus import __version__
from pkwbus.master.events import (
    Event,
    Exchanged,
    JobDone,
    Overrun,
    PkwLengthTold,
    SlaveDiagnosed,
    SlaveRestarted,
    SlaveStateChanged,
)
from pkwbus.master.planning.answers import ErrorKind
from pkwbus.master.planning.jobs import JobKind, JobResult
from pkwbus.master.planning.outcomes import JobOutcome, Rejected, metric_label
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.profibus.dp.slave import RestartReason, SlaveState
from pkwbus.service.metrics.exposition import CounterFamily, Series
from pkwbus.service.metrics.service_metrics import ApiMetrics, api_metrics

__all__ = [
    "DURATION_BUCKETS",
    "ERROR_KINDS",
    "ApiMetrics",
    "LineMetrics",
    "ServiceMetrics",
    "api_metrics",
    "fault_labels",
]

ERROR_KINDS = [k.value for k in ErrorKind if k is not ErrorKind.PORT]
DURATION_BUCKETS = (0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5, 1.0, 2.0)


# The fault_code of an answer that carries no fault number ("no change rights"):
# an empty label value would be no label at all to Prometheus, and a blank legend.
NO_FAULT_NUMBER = "-"


def fault_labels(fault: int | None, short: str) -> tuple[str, str]:
    """The ``fault_code`` and ``fault`` labels of ``pkwbus_pkw_faults_total``."""
    return (NO_FAULT_NUMBER if fault is None else str(fault), short)


class ServiceMetrics:
    """The service's own counters; one :class:`LineMetrics` per line feeds them."""

    def __init__(self, registry: CollectorRegistry) -> None:
        # The live list of the DP slaves, by drive, as their lines report them.
        ld = ["line", "drive"]
        self.faults = CounterFamily(
            "pkwbus_pkw_faults",
            "Drive rejections by fault number and text",
            [*ld, "fault_code", "fault"],
            registry=registry,
        )
        self.errors = CounterFamily(
            "pkwbus_telegram_errors",
            "Exchanges without a usable answer, by kind",
            [*ld, "kind"],
            registry=registry,
        )
        self.telegrams = CounterFamily(
            "pkwbus_telegrams", "Telegram exchanges attempted", ld, registry=registry
        )
        self.jobs = CounterFamily(
            "pkwbus_jobs",
            "Finished jobs by kind and outcome",
            [*ld, "kind", "outcome"],
            registry=registry,
        )
        self.retries = CounterFamily(
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
        self.busy = CounterFamily(
            "pkwbus_line_busy_seconds",
            "Time the line carried a transaction (rate() = utilisation)",
            ["line"],
            registry=registry,
        )
        self.overruns = CounterFamily(
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
        # USS: 1 while a drive's answers show another PKW length than configured
        # (protocol.pkw_length); no change goes out to it meanwhile. A series per
        # drive of a USS line.
        self.pkw_conflict = Gauge(
            "pkwbus_drive_pkw_length_conflict",
            "USS: 1 while the drive answers with another PKW length than configured"
            " (no write goes out to it), else 0",
            ld,
            registry=registry,
        )
        # PROFIBUS DP slaves: the families are there from the start; their series
        # come with the DP lines of a configuration.
        self.dp_state = Gauge(
            "pkwbus_dp_slave_state",
            "PROFIBUS DP: 1 for the slave's current state",
            [*ld, "state"],
            registry=registry,
        )
        self.dp_restarts = CounterFamily(
            "pkwbus_dp_restarts",
            "PROFIBUS DP: times a slave had to be parametrised again, by reason",
            [*ld, "reason"],
            registry=registry,
        )
        self.dp_diagnostics = CounterFamily(
            "pkwbus_dp_diagnostics",
            "PROFIBUS DP: diagnosis flags seen, by flag",
            [*ld, "flag"],
            registry=registry,
        )

    def for_line(
        self,
        line: str,
        drives: Mapping[str, Dialect],
        *,
        uss: bool = False,
        dp: bool = False,
    ) -> LineMetrics:
        """The counters of ``line``; ``drives`` maps each configured drive to its dialect,
        ``uss``: a USS line, whose drives' PKW length can contradict the configuration;
        ``dp``: a PROFIBUS DP line, whose slaves have states."""
        return LineMetrics(self, line, drives, uss=uss, dp=dp)


class LineMetrics:
    """A line's stream of events, turned into counter increments (an observer of it).

    A labelled counter has no series until its first increment, and
    ``increase()``/``rate()`` cannot see that first step (no earlier sample).
    Where an alert or a dashboard panel must see a single event, the series
    exists at 0 from the start ("Avoid missing metrics", Prometheus
    instrumentation practices):

    - ``pkwbus_pkw_faults_total``: every fault number of each configured
      drive's dialect table with its short text, and "no change rights"
      where the dialect has that answer (alert ``PkwbusDriveFaults``,
      dashboard fault panel). A number outside the table, or a drive not in
      the configuration, appears at its first fault;
    - ``pkwbus_line_busy_seconds_total`` and
      ``pkwbus_transaction_duration_seconds`` per line (alert
      ``PkwbusLineOverloaded``; one series per line);
    - ``pkwbus_poll_overruns_total`` per drive (dashboard panel "Poll
      overruns": one series per drive, and a first overrun is a rare event
      that must show);
    - on a DP line, ``pkwbus_dp_slave_state`` for each slave and state (1 for
      the current one, 0 for the others) and ``pkwbus_dp_restarts_total`` for
      each reason. Diagnosis flags appear when first seen.

    The other counters appear at their first increment: a zero series for
    each drive and kind would be most of the scrape (eight lines of 126
    drives: 20,000 series). ``pkwbus_telegrams_total`` and read jobs move at
    the first poll; ``pkwbus_telegram_errors_total`` feeds the alert
    ``PkwbusTelegramErrorRateRising`` as a share sustained over minutes, which
    the missing first step does not change; ``pkwbus_jobs_total`` and
    ``pkwbus_job_retries_total`` are dashboard rates.
    """

    def __init__(
        self,
        m: ServiceMetrics,
        line: str,
        drives: Mapping[str, Dialect],
        *,
        uss: bool = False,
        dp: bool = False,
    ) -> None:
        self._m = m
        self._line = line
        self._uss, self._dp = uss, dp
        self._busy = m.busy.labels(line, zero=True)
        self._duration = m.duration.labels(line)
        self._faults: dict[tuple[str, ...], Series] = {}
        self._telegrams: dict[str, Series] = {}
        self._retries: dict[str, Series] = {}
        self._overruns: dict[str, Series] = {}
        self._errors: dict[tuple[str, str], Series] = {}
        self._jobs: dict[tuple[str, str, JobOutcome], Series] = {}
        self._states: dict[str, dict[SlaveState, Any]] = {}
        self._restarts: dict[tuple[str, RestartReason], Series] = {}
        self._leaving: set[str] = set()  # drives taken away with an exchange out
        for d, dialect in drives.items():
            self.add_drive(d, dialect)
        self._on: dict[type, Callable[[Any], None]] = {
            Exchanged: self._exchanged,
            JobDone: self._job_done,
            Overrun: self._overrun,
            PkwLengthTold: self._pkw_length,
            SlaveStateChanged: self._slave_state,
            SlaveRestarted: self._restarted,
            SlaveDiagnosed: self._diagnosed,
        }

    def add_drive(self, d: str, dialect: Dialect) -> None:
        """A drive's series (at the start, or a drive a reload added to the line)."""
        m, line = self._m, self._line
        if self._uss:  # at 0 from the start: an alert or a panel sees the first conflict
            m.pkw_conflict.labels(line, d).set(0)
        for n, short in pkw.rejections(dialect):
            labels = fault_labels(n, short)
            self._faults[(d, *labels)] = m.faults.labels(line, d, *labels, zero=True)
        self._telegrams[d] = m.telegrams.labels(line, d)
        self._retries[d] = m.retries.labels(line, d)
        self._overruns[d] = m.overruns.labels(line, d, zero=True)
        for k in ERROR_KINDS:
            self._errors[(d, k)] = m.errors.labels(line, d, k)
        for kind in ("read", "write"):
            for outcome in JobOutcome:
                self._jobs[(d, kind, outcome)] = m.jobs.labels(line, d, kind, outcome.value)
        if self._dp:
            self._states[d] = {s: m.dp_state.labels(line, d, s.value) for s in SlaveState}
            for r in RestartReason:
                self._restarts[(d, r)] = m.dp_restarts.labels(line, d, r.value, zero=True)

    def forget_drive(self, d: str, *, exchange_out: bool = False) -> None:
        """A drive a reload took from the line: its counts here (its series go with
        :func:`~pkwbus.service.metrics.forget.forget_series`); ``exchange_out``: an exchange
        of it was out, whose end is the line's time alone (a drive of its name may be back)."""
        if exchange_out:
            self._leaving.add(d)
        self._faults = {k: v for k, v in self._faults.items() if k[0] != d}
        self._errors = {k: v for k, v in self._errors.items() if k[0] != d}
        self._jobs = {k: v for k, v in self._jobs.items() if k[0] != d}
        self._restarts = {k: v for k, v in self._restarts.items() if k[0] != d}
        for by_drive in (self._telegrams, self._retries, self._overruns):
            by_drive.pop(d, None)
        self._states.pop(d, None)

    def on_events(self, events: Sequence[Event]) -> None:
        on = self._on
        for event in events:
            handler = on.get(type(event))
            if handler is not None:
                handler(event)

    def _exchanged(self, event: Exchanged) -> None:
        error, drive, busy = event.error, event.drive, event.busy
        gone = drive in self._leaving  # one exchange is out at a time: the first to end
        if gone:
            self._leaving.discard(drive)
        if error is ErrorKind.PORT:
            return  # nothing went on the wire
        self._busy.inc(busy)
        telegrams = None if gone else self._telegrams.get(drive)
        if telegrams is None:
            return  # a drive a reload removed with its exchange out: the line's time alone
        telegrams.inc()
        if error is not None:
            self._errors[(drive, error.value)].inc()
        elif event.answered is not None:
            self._duration.observe(event.answered)

    def _job_done(self, event: JobDone) -> None:
        self.job_finished(event.drive, event.kind, event.result)

    def job_finished(self, drive: str, kind: JobKind, result: JobResult) -> None:
        outcome = result.outcome
        label = metric_label(outcome)
        key = (drive, kind, label)  # a StrEnum is the same key as its text
        child = self._jobs.get(key)
        if child is None:
            child = self._m.jobs.labels(self._line, drive, kind.value, label.value)
            self._jobs[key] = child
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

    def _overrun(self, event: Overrun) -> None:
        if (overruns := self._overruns.get(event.drive)) is not None:
            overruns.inc()

    def _pkw_length(self, event: PkwLengthTold) -> None:
        if event.drive not in self._telegrams:
            return
        conflict = event.length.in_conflict
        self._m.pkw_conflict.labels(self._line, event.drive).set(int(conflict))

    def _slave_state(self, event: SlaveStateChanged) -> None:
        for s, gauge in self._states[event.drive].items():
            gauge.set(1 if s is event.state else 0)

    def _restarted(self, event: SlaveRestarted) -> None:
        self._restarts[(event.drive, event.reason)].inc()

    def _diagnosed(self, event: SlaveDiagnosed) -> None:
        for flag in sorted(event.diagnosis.flags):
            self._m.dp_diagnostics.labels(self._line, event.drive, flag).inc()
