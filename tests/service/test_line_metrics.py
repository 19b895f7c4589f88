"""LineMetrics: events become increments of the right series (label children are cached)."""

from __future__ import annotations

from prometheus_client import CollectorRegistry

from pkwbus.master.jobs import Cancelled, Job, JobKind, JobResult, Priority
from pkwbus.master.transaction import Answered, Rejected, Tally, TimedOut
from pkwbus.protocol import pkw
from pkwbus.protocol.dialects import FC
from pkwbus.service.metrics import ServiceMetrics, outcome_label


def _job(kind: JobKind) -> Job:
    return Job("d1", pkw.read(FC, 1613), kind, Priority.POLL, 0.0)


def test_finished_jobs_count_by_kind_and_outcome() -> None:
    registry = CollectorRegistry()
    metrics = ServiceMetrics(registry).for_line("l", ["d1"])
    response = pkw.ValueResponse(1, 1613, 0, 5, pkw.Width.WORD)
    for _ in range(3):
        metrics.job_finished("d1", _job(JobKind.READ), JobResult(Answered(response), tally=Tally()))
    metrics.job_finished("d1", _job(JobKind.WRITE), JobResult(Rejected(3, "x", "y")))
    metrics.job_finished("d1", _job(JobKind.READ), JobResult(TimedOut("gone")))
    metrics.job_finished("other", _job(JobKind.READ), JobResult(Cancelled("stop")))

    def jobs(drive: str, kind: str, outcome: str) -> float | None:
        labels = {"line": "l", "drive": drive, "kind": kind, "outcome": outcome}
        return registry.get_sample_value("pkwbus_jobs_total", labels)

    assert jobs("d1", "read", "ok") == 3
    assert jobs("d1", "write", "rejected") == 1
    assert jobs("d1", "read", "timeout") == 1
    assert jobs("d1", "write", "ok") == 0  # initialised from the configuration
    assert jobs("other", "read", "cancelled") == 1  # a drive not configured still counts


def test_outcome_labels() -> None:
    response = pkw.ValueResponse(1, 1613, 0, 5, pkw.Width.WORD)
    assert outcome_label(Answered(response)).value == "ok"
    assert outcome_label(Rejected(None, "", "")).value == "rejected"
    assert outcome_label(Cancelled("")).value == "cancelled"
    assert outcome_label(TimedOut("")).value == "timeout"
