"""Soak: the service runtime at full line load against faulty simulated drives.

Two lines (FC and USS), each on its own simulator over TCP, every answer
exposed to drop, corrupt, garbage, truncate, stale and late faults (2 % each)
and to PKW lag. Checks, over the whole run:

(a) every value the master put in the snapshot decodes from a value the
    simulator actually sent in a valid telegram for that drive, PNU and index;
(b) the master's counters reconcile with what the simulator saw and injected;
(c) no growth of RSS or open file descriptors between the first and last quarter.

The CI form runs 60 s; the slow form (``-m slow``) 10 minutes.
"""

from __future__ import annotations

import asyncio
import gc
import os
import statistics
from dataclasses import dataclass, field
from typing import Any

import pytest
from prometheus_client import CollectorRegistry

from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimFaults, SimTiming, Simulator

from .helpers import WireLog, config_text, fc_line, open_fds, record_wire, rss_bytes, uss_line

FAULTS = SimFaults(
    drop=0.02, corrupt=0.02, garbage=0.02, truncate=0.02, stale=0.02, late=0.02, late_seconds=0.4
)
FC_POLLS = ["16-13", "16-14", "16-10", "16-30", "16-90"]
USS_POLLS = ["r0021", "r0024", "r0027", "r0032"]
SOAK_SECONDS = float(os.environ.get("PKWBUS_SOAK_SECONDS", "60"))
LONG_SOAK_SECONDS = float(os.environ.get("PKWBUS_LONG_SOAK_SECONDS", "600"))


class CheckedReadings(dict[ReadingKey, Reading]):
    """The snapshot's readings; every value stored is checked against the wire at once."""

    def __init__(self, check: Any) -> None:
        super().__init__()
        self.check = check
        self.stored = 0

    def __setitem__(self, key: ReadingKey, reading: Reading) -> None:
        self.check(key, reading)
        self.stored += 1
        super().__setitem__(key, reading)


@dataclass
class Soak:
    runtime: Runtime
    sims: dict[str, Simulator]  # by line
    wires: dict[str, WireLog]
    where: dict[str, tuple[str, int]]  # drive name: line, address
    bad_values: list[str] = field(default_factory=list)
    samples: list[tuple[int, int]] = field(default_factory=list)  # rss, fds

    def check(self, key: ReadingKey, reading: Reading) -> None:
        drive, parameter, index = key
        line, address = self.where[drive]
        entry = self.runtime.drives[drive]
        poll = next(p for p in entry.polls if (p.parameter, p.index) == (parameter, index))
        sent = self.wires[line].values.get((address, poll.request.pnu, poll.request.subindex))
        allowed = [poll.fmt.value_of(r) for r in sent or ()]
        if (reading.raw, reading.value) not in allowed:
            self.bad_values.append(f"{key}: {reading.raw}/{reading.value!r} never sent")


def counter(registry: CollectorRegistry, name: str, **labels: str) -> float:
    value = registry.get_sample_value(name, labels)
    return 0.0 if value is None else value


async def start_soak() -> tuple[Soak, list[Any]]:
    sims = {
        "fc": Simulator(
            "fc", [1, 2, 3], timing=SimTiming(0.002, lag_telegrams=1), faults=FAULTS, seed=1,
            catalog="danfoss-fc",
        ),
        "uss": Simulator(
            "uss", [1, 2], timing=SimTiming(0.002, lag_telegrams=1, lag_mode="stale"),
            faults=FAULTS, seed=2, catalog="siemens-g120",
        ),
    }  # fmt: skip
    wires = {name: record_wire(sim) for name, sim in sims.items()}
    ends = [await sim.serve_tcp("127.0.0.1", 0) for sim in sims.values()]
    text = config_text(
        [
            fc_line("fc", ends[0].url, [1, 2, 3], FC_POLLS, pause="15ms"),
            uss_line("uss", ends[1].url, [1, 2], USS_POLLS, pause="15ms"),
        ]
    )
    config = parse_config(text, environ={})
    runtime = await build_runtime(config)
    where = {d.name: (line.name, d.address) for line, d in config.drives()}
    soak = Soak(runtime, sims, wires, where)
    runtime.snapshot.readings = CheckedReadings(soak.check)
    return soak, ends


async def run_soak(seconds: float) -> None:
    tasks_before = len(asyncio.all_tasks())
    soak, ends = await start_soak()
    runtime = soak.runtime
    await runtime.start()
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    try:
        while loop.time() < end:
            await asyncio.sleep(min(1.0, seconds / 40))
            gc.collect()
            soak.samples.append((rss_bytes(), open_fds()))
            snap = runtime.snapshot.copy()  # what a scrape sees: must be values that were sent
            for key, reading in snap.readings.items():
                soak.check(key, reading)
    finally:
        await runtime.stop()
        await asyncio.sleep(0.5)  # answers (late ones too) still in flight reach the simulator
        for e in ends:
            await e.close()
    assert not soak.bad_values, soak.bad_values[:10]
    readings = runtime.snapshot.readings
    assert isinstance(readings, CheckedReadings)
    assert readings.stored > seconds * 20, "the lines hardly polled"
    reconcile(soak)
    no_growth(soak.samples)
    await asyncio.sleep(0.1)
    assert len(asyncio.all_tasks()) <= tasks_before


def reconcile(soak: Soak) -> None:
    """Master counters against the simulator's, per drive.

    How the master counts (service/metrics/instrumentation.py, master/line.py): every exchange
    that put a telegram on the wire adds 1 to ``pkwbus_telegrams_total``; one
    without a usable answer adds 1 to ``pkwbus_telegram_errors_total`` of its
    kind (timeout, checksum, length, address); ``unexpected`` (an answer that
    is not the one asked for: lag, stale) is added per finished job from its
    tally. The simulator answers each request once, after at most one fault.

    With nothing else on the line, each injected fault maps onto one exchange
    result: drop and late -> timeout; corrupt -> checksum; truncate -> length;
    garbage (noise without STX before a good telegram) -> a good answer.
    A late answer, though, arrives later, in some other exchange (or in the
    pause before one, where it is discarded). Landing in an exchange, it is
    taken as that exchange's answer (a reply if from the same drive,
    ``address`` if from another), and the exchange's own answer then falls
    into the configured 15 ms pause and is dropped: one late answer changes
    the class of at most one other exchange. So per line:

        |errors[kind] - natural[kind]| <= late answers sent, address <= late.
    """
    registry = soak.runtime.registry
    for drive, (line, address) in soak.where.items():
        stats = soak.sims[line].stats.as_dict()
        sim = stats["per_drive"][str(address)]
        injected = sim["injected"]
        telegrams = counter(registry, "pkwbus_telegrams_total", line=line, drive=drive)

        def errors(kind: str, line: str = line, drive: str = drive) -> float:
            return counter(
                registry, "pkwbus_telegram_errors_total", line=line, drive=drive, kind=kind
            )

        # Exact: every exchange the master counts is one request the drive got.
        # (TCP loses nothing; the master sends only well-formed telegrams.)
        assert telegrams == sim["requests"] > 0, (drive, telegrams, sim)
        assert soak.wires[line].requests[address] == sim["requests"]
        # Exact on the simulator's side: an answer for every request but the dropped ones.
        assert sim["responses"] == sim["requests"] - injected["drop"]
        late_on_line = stats["injected"]["late"]
        got_all = {k: errors(k) for k in ("timeout", "checksum", "length", "address", "unexpected")}
        print(f"{drive}: telegrams {telegrams:.0f} errors {got_all} sim {sim}")
        natural = {
            "timeout": injected["drop"] + injected["late"],
            "checksum": injected["corrupt"],
            "length": injected["truncate"],
            "address": 0,
        }
        for kind, expected in natural.items():
            got = errors(kind)
            assert abs(got - expected) <= late_on_line, (drive, kind, got, expected, stats)
        # Unexpected answers come from lag (one AK 0 or stale answer per request), stale
        # faults and late answers; the tallies of polls in flight at stop are not counted.
        unexpected = errors("unexpected")
        assert 0 < unexpected <= sim["lagged"] + injected["stale"] + late_on_line
        assert unexpected >= sim["lagged"] * 0.5


def no_growth(samples: list[tuple[int, int]]) -> None:
    quarter = max(1, len(samples) // 4)
    first, last = samples[:quarter], samples[-quarter:]
    rss_growth = statistics.median(s[0] for s in last) - statistics.median(s[0] for s in first)
    fd_growth = max(s[1] for s in last) - max(s[1] for s in first)
    assert rss_growth < 8 * 2**20, f"RSS grew by {rss_growth / 2**20:.1f} MiB"
    assert fd_growth <= 2, f"{fd_growth} more file descriptors"


@pytest.mark.soak
@pytest.mark.long
async def test_soak_ci() -> None:
    await run_soak(SOAK_SECONDS)


@pytest.mark.soak
@pytest.mark.slow
async def test_soak_long() -> None:
    await run_soak(LONG_SOAK_SECONDS)
