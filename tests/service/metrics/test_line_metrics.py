"""LineMetrics: events become increments of the right series (label children are cached)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from prometheus_client import CollectorRegistry

from pkwbus.master.carriers import carrier_for
from pkwbus.master.events import Exchanged, Overrun
from pkwbus.master.planning.answers import ErrorKind
from pkwbus.master.planning.jobs import Cancelled, JobKind, JobResult
from pkwbus.master.planning.outcomes import Answered, Rejected, TimedOut, metric_label
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.planning.transaction import Tally
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.snapshot_writer import SnapshotWriter
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import DIALECTS, FC, Dialect, Reply
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.service.metrics.instrumentation import ServiceMetrics

FAULTS = "pkwbus_pkw_faults_total"


def test_finished_jobs_count_by_kind_and_outcome() -> None:
    registry = CollectorRegistry()
    metrics = ServiceMetrics(registry).for_line("l", {"d1": FC})
    response = pkw.ValueResponse(1, 1613, 0, 5, pkw.Width.WORD)
    for _ in range(3):
        metrics.job_finished("d1", JobKind.READ, JobResult(Answered(response), tally=Tally()))
    metrics.job_finished("d1", JobKind.WRITE, JobResult(Rejected(3, "x", "y")))
    metrics.job_finished("d1", JobKind.READ, JobResult(TimedOut("gone")))
    metrics.job_finished("other", JobKind.READ, JobResult(Cancelled("stop")))

    def jobs(drive: str, kind: str, outcome: str) -> float | None:
        labels = {"line": "l", "drive": drive, "kind": kind, "outcome": outcome}
        return registry.get_sample_value("pkwbus_jobs_total", labels)

    assert jobs("d1", "read", "ok") == 3
    assert jobs("d1", "write", "rejected") == 1
    assert jobs("d1", "read", "timeout") == 1
    assert jobs("d1", "write", "ok") is None  # no series before the first such job
    assert jobs("other", "read", "cancelled") == 1  # a drive not configured still counts


def _exported(registry: CollectorRegistry) -> set[str]:
    return {sample.name for family in registry.collect() for sample in family.samples}


def test_only_the_counters_an_alert_needs_at_zero_exist_before_they_move() -> None:
    """Faults (alert PkwbusDriveFaults), the line's busy time and poll overruns (a panel of
    rare events) exist at 0; the per-drive counters that move at the first poll, or feed
    rates only, appear at their first step."""
    registry = CollectorRegistry()
    metrics = ServiceMetrics(registry).for_line("l", {"d1": FC})
    exported = _exported(registry)
    assert {FAULTS, "pkwbus_line_busy_seconds_total", "pkwbus_poll_overruns_total"} <= exported
    assert (
        registry.get_sample_value("pkwbus_poll_overruns_total", {"line": "l", "drive": "d1"}) == 0
    )
    quiet = {
        "pkwbus_telegram_errors_total",
        "pkwbus_telegrams_total",
        "pkwbus_jobs_total",
        "pkwbus_job_retries_total",
    }
    assert not quiet & exported
    metrics.on_events([Exchanged("d1", ErrorKind.TIMEOUT, 0.01), Overrun("d1")])
    kinds = {
        sample.labels["kind"]: sample.value
        for family in registry.collect()
        for sample in family.samples
        if sample.name == "pkwbus_telegram_errors_total"
    }
    assert kinds == {"timeout": 1}
    assert (
        registry.get_sample_value("pkwbus_poll_overruns_total", {"line": "l", "drive": "d1"}) == 1
    )


def test_the_read_models_counts_agree_with_the_exported_counters() -> None:
    """The status page's plain counts, kept by the snapshot's writer from the same events:
    what /metrics says, without a collect()."""
    registry = CollectorRegistry()
    metrics = ServiceMetrics(registry).for_line("l", {"d1": FC, "d2": FC})
    snapshot = Snapshot()
    specs = [
        DriveSpec(d, carrier_for(DriveTarget.create("fc", n)))
        for n, d in enumerate(("d1", "d2"), 1)
    ]
    writer = SnapshotWriter("l", specs, snapshot)
    for drive, error in [
        ("d1", ErrorKind.TIMEOUT),
        ("d2", ErrorKind.CHECKSUM),
        ("d1", ErrorKind.PORT),  # nothing went on the wire
        ("d2", ErrorKind.TIMEOUT),
        ("d1", None),
    ]:
        events = [Exchanged(drive, error, 0.01)]
        writer.apply(events)
        metrics.on_events(events)
    samples = [s for family in registry.collect() for s in family.samples]
    exported = sum(s.value for s in samples if s.name == "pkwbus_telegrams_total")
    assert snapshot.totals["l"].telegrams == exported == 4
    errors = {
        d: sum(s.value for s in samples
               if s.name == "pkwbus_telegram_errors_total" and s.labels["drive"] == d)
        for d in ("d1", "d2")
    }  # fmt: skip
    assert {d: snapshot.counts[d].errors for d in errors} == errors == {"d1": 1, "d2": 2}
    busy = registry.get_sample_value("pkwbus_line_busy_seconds_total", {"line": "l"})
    assert snapshot.totals["l"].busy == pytest.approx(busy) == pytest.approx(0.04)


def test_outcome_labels() -> None:
    response = pkw.ValueResponse(1, 1613, 0, 5, pkw.Width.WORD)
    assert metric_label(Answered(response)).value == "ok"
    assert metric_label(Rejected(None, "", "")).value == "rejected"
    assert metric_label(Cancelled("")).value == "cancelled"
    assert metric_label(TimedOut("")).value == "timeout"


def _fault_series(registry: CollectorRegistry) -> dict[frozenset[tuple[str, str]], float]:
    return {
        frozenset(sample.labels.items()): sample.value
        for family in registry.collect()
        for sample in family.samples
        if sample.name == FAULTS
    }


def _rejected(dialect: Dialect, reply: Reply, fault: int) -> Rejected:
    """A rejection as the transaction makes it from the drive's telegram."""
    ak = pkw.response_id(dialect, reply)
    raw = pkw.encode_response(
        pkw.Rejection(ak, 100, 0, fault, "", ""), dialect, dialect.default_ind_layout, None
    )
    response = pkw.decode_response(raw, dialect, dialect.default_ind_layout)
    assert isinstance(response, pkw.Rejection)
    return Rejected(response.fault, response.text, response.short)


def _rejections(dialect: Dialect) -> list[Rejected]:
    answers = [_rejected(dialect, Reply.REJECTED, number) for number in dialect.faults]
    if any(reply is Reply.NO_RIGHTS for reply, _ in dialect.responses.values()):
        answers.append(_rejected(dialect, Reply.NO_RIGHTS, 0))
    return answers


@pytest.mark.parametrize("dialect", DIALECTS.values(), ids=lambda d: d.name)
def test_first_fault_of_each_code_is_a_step_from_zero(dialect: Dialect) -> None:
    """Every fault a drive's dialect knows has its series at 0 before it happens, with the
    labels the fault itself brings, so that increase() sees 0 -> 1."""
    answers = _rejections(dialect)
    assert len(answers) > len(dialect.faults) / 2
    for answer in answers:
        registry = CollectorRegistry()
        metrics = ServiceMetrics(registry).for_line("l", {"d1": dialect, "d2": dialect})
        before = _fault_series(registry)
        assert before, "no fault series before the first fault"
        assert set(before.values()) == {0.0}
        metrics.job_finished("d1", JobKind.WRITE, JobResult(answer))
        after = _fault_series(registry)
        assert after.keys() == before.keys(), f"{answer}: a new series, not a step from 0"
        changed = {labels: v for labels, v in after.items() if v != before[labels]}
        assert len(changed) == 1, answer
        labels, value = changed.popitem()
        assert value == 1
        assert dict(labels)["drive"] == "d1"
    # one series per drive and per answer, none shared between two answers
    assert len(before) == 2 * len(answers)


def test_a_fault_outside_the_table_still_counts() -> None:
    registry = CollectorRegistry()
    metrics = ServiceMetrics(registry).for_line("l", {"d1": FC})
    unknown = _rejected(FC, Reply.REJECTED, 77)
    before = _fault_series(registry)
    metrics.job_finished("d1", JobKind.READ, JobResult(unknown))
    new = _fault_series(registry).keys() - before.keys()
    assert [dict(labels)["fault_code"] for labels in new] == ["77"]


def test_the_service_creates_the_fault_series_of_its_configured_drives(tmp_path: Path) -> None:
    config = parse_config(
        f"""\
audit_db: {tmp_path / "audit.sqlite"}
lines:
  - name: hall
    port: {tmp_path / "no-such-tty"}
    protocol: uss
    baudrate: 19200
    drives:
      - {{name: fan, address: 1}}
      - {{name: pump, address: 2, dialect: danfoss-pcv}}
"""
    )

    async def series() -> dict[frozenset[tuple[str, str]], float]:
        runtime = await build_runtime(config)
        try:
            return _fault_series(runtime.registry)
        finally:
            await runtime.stop()

    found = asyncio.run(series())
    for drive in config.lines[0].drives:
        mine = {labels for labels in found if ("drive", drive.name) in labels}
        assert len(mine) == len(_rejections(drive.pkw_dialect)), drive.name
    assert set(found.values()) == {0.0}


def test_every_fault_series_has_a_fault_code_prometheus_keeps() -> None:
    """An empty label value is no label to Prometheus: "no change rights" has no fault
    number, and its series still carries a fault_code a legend can show."""
    registry = CollectorRegistry()
    ServiceMetrics(registry).for_line("l", {d.name: d for d in DIALECTS.values()})
    codes = {dict(labels)["fault_code"] for labels in _fault_series(registry)}
    assert codes and "" not in codes
