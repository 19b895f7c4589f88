"""The soak's own checks, on made-up samples and a simulated line: each can fail."""

from __future__ import annotations

from dataclasses import replace

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import FC
from pkwbus.sim import ModelConfig, SimFaults, SimTiming, Simulator
from tests.sim.conftest import request_telegram

from .plan import service_config, soak_lines, write_value
from .record import SentValues
from .samples import MIB, WAL_MAX, Sample, judge, table, warmup

QUIET = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0)


def run(minutes: int, **grow: float) -> list[Sample]:
    """A sample a minute; each field grows by ``grow[field]`` a minute (a leak)."""
    base = Sample(0.0, 60 * MIB, 20, 6, 40_960, 2 * MIB, 0, 0)
    return [
        replace(
            base,
            seconds=60.0 * m,
            writes=20 * m,
            **{k: getattr(base, k) + int(v * m) for k, v in grow.items()},
        )
        for m in range(1, minutes + 1)
    ]


def test_flat_samples_pass() -> None:
    assert judge(run(60), warmup(3600)) == []


@pytest.mark.parametrize(
    ("field", "per_minute", "says"),
    [
        ("rss", 0.3 * MIB, "RSS grew"),  # 18 MiB an hour
        ("fds", 0.2, "descriptors grew"),  # a descriptor every 5 minutes
        ("threads", 0.2, "threads grew"),
        ("wal", 0.2 * MIB, "WAL reached"),  # never checkpointed
        ("audit", 200 * 1024, "audit database grew"),  # 10 KiB a write
    ],
)
def test_growth_that_goes_on_fails(field: str, per_minute: float, says: str) -> None:
    problems = judge(run(60, **{field: per_minute}), warmup(3600))
    assert len(problems) == 1 and says in problems[0], problems


def test_growth_that_levels_off_after_the_warm_up_passes() -> None:
    samples = run(60)
    # 30 MiB and 5 threads more in the first 10 minutes, then flat.
    grown = [
        replace(s, rss=s.rss + int(min(s.seconds, 600)) * 50_000, threads=s.threads + 5)
        for s in samples
    ]
    assert judge(grown, warmup(3600)) == []


def test_a_port_lost_at_the_instant_of_a_few_samples_is_no_leak() -> None:
    samples = run(60)
    dips = [replace(s, fds=s.fds - 5) if i % 7 == 0 else s for i, s in enumerate(samples)]
    assert judge(dips, warmup(3600)) == []


def test_too_few_samples_are_not_judged_a_pass() -> None:
    assert "too short" in judge(run(2), warmup(120))[0]
    assert WAL_MAX > 4 * MIB  # room above SQLite's checkpoint at 1000 pages


def test_the_table_has_a_row_per_sample() -> None:
    text = table(run(3))
    assert len(text.splitlines()) == 4 and "RSS MiB" in text.splitlines()[0]


def test_values_sent_are_known_and_others_are_not() -> None:
    sim = Simulator("fc", [1, 2], timing=SimTiming(0.0), seed=1, catalog="danfoss-fc", model=QUIET)
    sent = SentValues(sim)
    for address in (1, 2):
        assert sim.handle(request_telegram(address, pkw.read(FC, 341), FC)) is not None
    ramp = sim.drives[1].params.number(341)
    assert sent.sent((1, 341, 0), ramp) is True
    assert sent.sent((1, 341, 0), ramp + 0.01) is False  # one raw step off
    assert sent.sent((1, 342, 0), ramp) is None  # never asked


def test_an_answer_that_did_not_arrive_whole_is_not_a_value_sent() -> None:
    faults = SimFaults(corrupt=1.0)
    sim = Simulator("fc", [1], timing=SimTiming(0.0), seed=1, faults=faults, model=QUIET)
    sent = SentValues(sim)
    sim.handle(request_telegram(1, pkw.read(FC, 341), FC))
    assert sent.sent((1, 341, 0), sim.drives[1].params.number(341)) is None


def test_an_answer_with_another_drive_s_address_is_not_that_drive_s_value() -> None:
    faults = SimFaults(wrong_address=1.0)
    sim = Simulator("fc", [1, 2], timing=SimTiming(0.0), seed=1, faults=faults, model=QUIET)
    sent = SentValues(sim)
    sim.handle(request_telegram(1, pkw.read(FC, 341), FC))
    assert not sent.values


def test_the_plan_covers_every_protocol_and_port_kind_in_three_lines() -> None:
    lines = soak_lines(3)
    assert {line.protocol for line in lines} == {"fc", "uss", "profibus"}
    assert {line.end for line in lines} == {"tcp", "pty"}
    ports = {line.name: f"socket://127.0.0.1:{5000 + i}" for i, line in enumerate(lines)}
    config = service_config(lines, ports, listen="127.0.0.1:1", audit_db="a", token_env="T")
    assert [line["name"] for line in config["lines"]] == [line.name for line in lines]


def test_every_write_of_a_run_has_its_own_value() -> None:
    drives = [d for line in soak_lines(3) for d in line.drives if d.writable]
    for drive in drives:
        values = [write_value(drive, n) for n in range(1, 5000)]
        assert len(set(values)) == len(values) and min(values) >= 1 and max(values) <= 600
