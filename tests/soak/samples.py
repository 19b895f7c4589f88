"""What the soak samples of the service every minute, the table of it, and the verdict.

Growth that does not level off: after the warm-up (the first fifth of the run,
at most 10 minutes: caches fill, the thread pool and the audit WAL grow to
their size), the samples fall into three equal thirds; the last third may exceed the
middle third by no more than an allowance (RSS: their means; descriptors and
threads: their medians, which a port lost at the instant of one sample does
not move). A leak grows the last third past the middle one whatever the
noise; a quantity that levelled off has them equal. The allowances: RSS 4 MiB
or 3 %, whichever is more; 2 descriptors; 2 threads (the default executor
starts its threads on demand, up to its cap). The audit files are judged
otherwise: the WAL must stay bounded (SQLite's automatic checkpoint keeps it
near 1000 pages, 4 MiB), and the database file must grow by no more than
8 KiB per write attempt (a row, its index entry, pages half full).
"""

from __future__ import annotations

import os
import statistics
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "Sample",
    "judge",
    "proc_sample",
    "size",
    "table",
    "warmup",
]

MIB = 2**20
WAL_MAX = 8 * MIB
AUDIT_BYTES_PER_WRITE = 8 * 1024


@dataclass(frozen=True)
class Sample:
    """One minute's look at the service. ``stall``: the longest /healthz answer since the
    last sample (seconds); ``scrape``: the longest /metrics answer."""

    seconds: float
    rss: int
    fds: int
    threads: int
    audit: int  # the database file's bytes
    wal: int  # its write-ahead log's bytes
    log: int  # the service's log (stderr) bytes
    writes: int  # write attempts made so far
    stall: float = 0.0
    scrape: float = 0.0


def proc_sample(pid: int) -> tuple[int, int, int]:
    """RSS in bytes, open descriptors and threads of process ``pid`` (Linux /proc)."""
    status = Path(f"/proc/{pid}/status").read_text().splitlines()
    found = dict(line.split(":", 1) for line in status if ":" in line)
    rss = int(found["VmRSS"].split()[0]) * 1024
    threads = int(found["Threads"])
    return rss, len(os.listdir(f"/proc/{pid}/fd")), threads


def size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:
        return 0


def warmup(seconds: float) -> float:
    """The warm-up of a run that lasts ``seconds``: a fifth of it, at most 10 minutes."""
    return min(600.0, seconds / 5)


@dataclass(frozen=True)
class Rule:
    name: str
    get: Callable[[Sample], float]
    allowance: Callable[[float], float]  # of the middle third's level
    unit: Callable[[float], str]
    level: Callable[[list[float]], float] = statistics.fmean


RULES = (
    Rule("RSS", lambda s: s.rss, lambda m: max(4 * MIB, 0.03 * m), lambda v: f"{v / MIB:.1f} MiB"),
    Rule("descriptors", lambda s: s.fds, lambda m: 2, lambda v: f"{v:g}", statistics.median),
    Rule("threads", lambda s: s.threads, lambda m: 2, lambda v: f"{v:g}", statistics.median),
)


def judge(samples: list[Sample], warm: float) -> list[str]:
    """The problems: growth that does not level off, an unbounded WAL, an audit database
    that grows faster than its writes. Empty: none."""
    problems = []
    judged = [s for s in samples if s.seconds >= warm]
    if len(judged) < 3:
        return [f"only {len(judged)} samples after the warm-up: too short to judge"]
    third = len(judged) // 3
    middle, last = judged[-2 * third : -third], judged[-third:]
    for rule in RULES:
        before = rule.level([rule.get(s) for s in middle])
        after = rule.level([rule.get(s) for s in last])
        if after - before > rule.allowance(before):
            problems.append(
                f"{rule.name} grew from {rule.unit(before)} (middle third) to"
                f" {rule.unit(after)} (last third), more than {rule.unit(rule.allowance(before))}"
            )
    wal = max(s.wal for s in samples)
    if wal > WAL_MAX:
        problems.append(f"the audit WAL reached {wal / MIB:.1f} MiB (at most {WAL_MAX / MIB:g})")
    first, end = judged[0], judged[-1]
    writes = end.writes - first.writes
    grown = end.audit - first.audit
    if grown > AUDIT_BYTES_PER_WRITE * max(writes, 1):
        problems.append(
            f"the audit database grew by {grown} bytes for {writes} write attempts"
            f" (at most {AUDIT_BYTES_PER_WRITE} each)"
        )
    return problems


COLUMNS: tuple[tuple[str, Callable[[Sample], str]], ...] = (
    ("minute", lambda s: f"{s.seconds / 60:.1f}"),
    ("RSS MiB", lambda s: f"{s.rss / MIB:.1f}"),
    ("fds", lambda s: str(s.fds)),
    ("threads", lambda s: str(s.threads)),
    ("audit KiB", lambda s: f"{s.audit / 1024:.0f}"),
    ("WAL KiB", lambda s: f"{s.wal / 1024:.0f}"),
    ("log KiB", lambda s: f"{s.log / 1024:.0f}"),
    ("writes", lambda s: str(s.writes)),
    ("stall ms", lambda s: f"{s.stall * 1000:.0f}"),
    ("scrape ms", lambda s: f"{s.scrape * 1000:.0f}"),
)


def table(samples: list[Sample]) -> str:
    """The samples as a plain-text table, one row each."""
    rows = [[name for name, _ in COLUMNS]]
    rows += [[cell(s) for _, cell in COLUMNS] for s in samples]
    widths = [max(len(row[i]) for row in rows) for i in range(len(COLUMNS))]
    return "\n".join(
        "  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in rows
    )
