"""Small helpers shared by the benchmarks.

- :func:`measure_cpu` - a context manager that records the CPU time of this
  process (``time.process_time()``, user + system, all threads, no children),
  the wall time and the ``getrusage(RUSAGE_SELF)`` deltas of the block.
- :func:`cpu_per_op` - run a callable *n* times and report CPU and wall time
  per call.
- :func:`markdown_table` - format results as a Markdown table, for
  ``docs/benchmarks.md``.
- :func:`pty_pair` - a pair of linked pseudo-terminals made by ``socat``, the
  stand-in for an RS-485 line used by the serial benchmarks.
- :class:`BenchSetupError` - an expected failure (tool or package missing,
  peer does not start); scripts print its message and exit with status 2.
- :func:`module_command` - the command line of a benchmark module in another
  process (``python -m bench.NAME``, run with ``cwd=ROOT``).
"""

from __future__ import annotations

import contextlib
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

__all__ = [
    "BenchSetupError",
    "PtyPair",
    "Timing",
    "cpu_per_op",
    "markdown_table",
    "measure_cpu",
    "module_command",
    "pty_pair",
    "stop_process",
]


ROOT = Path(__file__).resolve().parent.parent  # the repository, where `python -m bench.NAME` runs


def module_command(name: str, *args: str) -> list[str]:
    """The command line of ``bench.NAME`` with ``args`` in another process; start it with
    ``cwd=ROOT``, where the package ``bench`` is found."""
    return [sys.executable, "-m", f"bench.{name}", *args]


class BenchSetupError(Exception):
    """Expected failure before or while setting up a benchmark.

    The message is meant for the user as is; scripts print it without a
    traceback and exit with status 2.
    """


@dataclass
class Timing:
    """CPU and wall time of a block, filled in when the block is left."""

    cpu_s: float = 0.0
    wall_s: float = 0.0
    utime_s: float = 0.0
    stime_s: float = 0.0
    ops: int = 0
    _start: tuple[float, float, float, float] = field(default=(0.0, 0.0, 0.0, 0.0), repr=False)

    @property
    def cpu_us_per_op(self) -> float:
        """CPU microseconds per operation (``ops`` must be set)."""
        return self.cpu_s * 1e6 / self.ops if self.ops else float("nan")

    @property
    def wall_us_per_op(self) -> float:
        """Wall-clock microseconds per operation (``ops`` must be set)."""
        return self.wall_s * 1e6 / self.ops if self.ops else float("nan")

    @property
    def ops_per_s(self) -> float:
        """Operations per second of wall time (``ops`` must be set)."""
        return self.ops / self.wall_s if self.wall_s > 0 else float("nan")

    @property
    def cpu_load(self) -> float:
        """CPU time divided by wall time: 1.0 is one core fully busy."""
        return self.cpu_s / self.wall_s if self.wall_s > 0 else float("nan")

    def as_dict(self) -> dict[str, float | int]:
        """The raw and derived figures as a flat dict."""
        return {
            "n": self.ops,
            "cpu_s": self.cpu_s,
            "wall_s": self.wall_s,
            "utime_s": self.utime_s,
            "stime_s": self.stime_s,
            "cpu_us_per_op": self.cpu_us_per_op,
            "wall_us_per_op": self.wall_us_per_op,
            "ops_per_s": self.ops_per_s,
            "cpu_load": self.cpu_load,
        }


def _now() -> tuple[float, float, float, float]:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return (time.process_time(), time.perf_counter(), ru.ru_utime, ru.ru_stime)


@contextlib.contextmanager
def measure_cpu(ops: int = 0) -> Iterator[Timing]:
    """Record this process's CPU time and the wall time spent in the block.

    ``ops`` (also settable on the yielded :class:`Timing` inside the block)
    is the number of operations done, for the per-operation figures. Only
    this process is counted: peers in other processes (a server, socat) are
    not, which is the point of the serial benchmarks.
    """
    timing = Timing(ops=ops)
    timing._start = _now()
    try:
        yield timing
    finally:
        cpu, wall, utime, stime = _now()
        cpu0, wall0, utime0, stime0 = timing._start
        timing.cpu_s = cpu - cpu0
        timing.wall_s = wall - wall0
        timing.utime_s = utime - utime0
        timing.stime_s = stime - stime0


def cpu_per_op(fn: Callable[[], object], n: int, warmup: int = 0) -> Timing:
    """Call ``fn()`` ``warmup`` times unmeasured, then ``n`` times measured."""
    if n <= 0:
        raise ValueError("n must be positive")
    for _ in range(warmup):
        fn()
    with measure_cpu(ops=n) as timing:
        for _ in range(n):
            fn()
    return timing


def _cell(value: object, digits: int) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        if value != value:  # NaN
            return "-"
        return f"{value:,.{digits}f}"
    return str(value).replace("|", "\\|")


def markdown_table(
    rows: Sequence[Mapping[str, object]],
    columns: Sequence[str] | Mapping[str, str] | None = None,
    *,
    digits: int = 0,
) -> str:
    """Format ``rows`` as a GitHub-flavoured Markdown table.

    ``columns`` picks and orders the keys; a mapping gives header titles
    (``{"cpu_us_per_op": "CPU us/op"}``). By default all keys of the first
    row are used. Numbers are right-aligned, floats shown with ``digits``
    decimals, missing cells left empty. No columns give an empty string.
    """
    if columns is None:
        columns = list(rows[0]) if rows else []
    titles = dict(columns) if isinstance(columns, Mapping) else {c: c for c in columns}
    keys = list(titles)
    if not keys:
        return ""
    numeric = {
        k: bool(rows)
        and all(isinstance(r.get(k), int | float) and not isinstance(r.get(k), bool) for r in rows)
        for k in keys
    }
    lines = [
        "| " + " | ".join(titles[k] for k in keys) + " |",
        "|" + "|".join("---:" if numeric[k] else "---" for k in keys) + "|",
    ]
    for row in rows:
        cells = [_cell(row[k], digits) if k in row else "" for k in keys]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def stop_process(proc: subprocess.Popen[bytes], timeout: float = 3.0) -> None:
    """Terminate ``proc`` (SIGTERM, then SIGKILL) and reap it; never raises."""
    if proc.poll() is None:
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            proc.wait()
    for stream in (proc.stdin, proc.stdout, proc.stderr):
        if stream is not None:
            stream.close()


class PtyPair(NamedTuple):
    """Two linked ptys: what is written to one can be read from the other."""

    a: str
    b: str
    socat_pid: int


@contextlib.contextmanager
def pty_pair(timeout: float = 5.0) -> Iterator[PtyPair]:
    """Yield two linked ptys made by ``socat``; stop socat afterwards.

    The links live in a fresh temporary directory that is removed afterwards.
    socat runs in its own session so that a Ctrl-C in the terminal reaches
    only us, and we stop it ourselves, in order.
    """
    if shutil.which("socat") is None:
        raise BenchSetupError(
            "socat is not installed; it makes the pty pair that stands in for the "
            "RS-485 line.\nInstall it with: apt-get install -y socat"
        )
    tmp = Path(tempfile.mkdtemp(prefix="pkwbus-bench-"))
    a, b, log = tmp / "a", tmp / "b", tmp / "socat.log"
    proc: subprocess.Popen[bytes] | None = None
    try:
        with log.open("wb") as log_file:  # socat keeps its own descriptor
            proc = subprocess.Popen(
                ["socat", "-d", "-d", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=log_file,
                start_new_session=True,
            )
        deadline = time.monotonic() + timeout
        while not (a.exists() and b.exists()):
            if proc.poll() is not None:
                err = log.read_text(errors="replace")
                raise BenchSetupError(f"socat exited with status {proc.returncode}:\n{err}")
            if time.monotonic() > deadline:
                raise BenchSetupError(f"socat did not create {a} and {b} within {timeout} s")
            time.sleep(0.01)
        yield PtyPair(str(a), str(b), proc.pid)
    finally:
        if proc is not None:
            stop_process(proc)
        shutil.rmtree(tmp, ignore_errors=True)
