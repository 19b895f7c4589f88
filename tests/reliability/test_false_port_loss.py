"""No false port loss: three pty lines, faulty simulators, a busy machine.

FC, USS and PROFIBUS DP simulators (``pkwbus simulate --pty``, each a process
of its own) answer late and put garbage before answers; two processes burn
CPU on the machine's cores meanwhile. The service polls the three lines as
fast as they answer. The simulators never close their ends, so no port may
be reported lost, while late answers and garbage keep the lines discarding
input that the loop has already found to read.

The minute-long form is ``-m long``; the short form runs a few seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import subprocess
import sys
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from pkwbus.link import LinkState
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config

from .helpers import config_text, fc_line, uss_line, wait_for

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux ptys")

LATE_AFTER = "15ms"
# Line -> the simulator's options and the drives' addresses.
LINES: dict[str, tuple[list[str], list[int]]] = {
    "fc": (["--protocol", "fc"], [1, 2, 3]),
    "uss": (["--protocol", "uss"], [1, 2]),
    "dp": (["--protocol", "profibus", "--dialect", "danfoss-pcv"], [8, 9]),
}
BURNERS = 2
# Seconds, and the probability of a late answer and of garbage before an answer.
SHORT = (5.0, 0.2)
LONG = (60.0, 0.05)


def dp_line_config(name: str, url: str, addresses: list[int]) -> dict[str, Any]:
    return {
        "name": name,
        "port": url,
        "protocol": "profibus",
        "baudrate": 187500,
        "drives": [
            {
                "name": f"{name}_d{a}",
                "address": a,
                "dialect": "danfoss-pcv",
                "ident": 0x0402,
                "catalog": "danfoss-fc",
                "poll": [{"parameter": p, "every": "20ms"} for p in ("16-13", "16-14")],
            }
            for a in addresses
        ],
    }


@dataclass
class Losses:
    """Every port loss a line reported, with its reason."""

    seen: list[tuple[str, str | None]] = field(default_factory=list)

    def listener(self, line: str) -> Any:
        def on_change(state: LinkState, error: str | None) -> None:
            if state is LinkState.FAILED:
                self.seen.append((line, error))

        return on_change


@contextlib.contextmanager
def burning(n: int) -> Iterator[None]:
    """``n`` processes that burn CPU while the block runs."""
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()


@contextlib.asynccontextmanager
async def simulators(folder: Path, faults: float) -> AsyncIterator[dict[str, Path]]:
    """The three simulators on ptys; yields each line's stats file once every pty is there."""
    procs: dict[str, subprocess.Popen[bytes]] = {}
    stats = {name: folder / f"{name}.json" for name in LINES}
    try:
        for seed, (name, (options, addresses)) in enumerate(LINES.items()):
            drives = ",".join(str(a) for a in addresses)
            command = [
                sys.executable, "-m", "pkwbus.sim", *options, "--pty", str(folder / name),
                "--drives", drives, "--response-delay", "2ms", "--late", str(faults),
                "--garbage", str(faults), "--late-after", LATE_AFTER, "--seed", str(seed),
                "--stats-file", str(stats[name]), "--stats-interval", "0.1s",
                "--warnings-per-hour", "0", "--trips-per-hour", "0",
            ]  # fmt: skip
            procs[name] = subprocess.Popen(
                command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
            )
        for name, proc in procs.items():
            path = folder / name
            await wait_for(lambda p=path, q=proc: p.exists() or q.poll() is not None, 60.0)
            assert proc.poll() is None, proc.communicate()[1].decode()
        yield stats
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)  # the simulator writes its stats and ends
        for proc in procs.values():
            try:
                proc.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.communicate()


def read_stats(path: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads(path.read_text())
    return data


async def run_lines(folder: Path, seconds: float, faults: float) -> None:
    losses = Losses()
    async with simulators(folder, faults) as stats:
        text = config_text(
            [
                fc_line("fc", str(folder / "fc"), LINES["fc"][1], ["16-13", "16-14"],
                        every="20ms", timeout="50ms"),
                uss_line("uss", str(folder / "uss"), LINES["uss"][1], ["r0021", "r0027"],
                         every="20ms", timeout="50ms"),
                dp_line_config("dp", str(folder / "dp"), LINES["dp"][1]),
            ]
        )  # fmt: skip
        runtime = await build_runtime(parse_config(text, environ={}))
        for name, runner in runtime.runners.items():
            runner.link.reconnect.add_listener(losses.listener(name))  # every bus alike
        with burning(min(BURNERS, os.cpu_count() or 1)):
            await runtime.start()
            try:
                await wait_for(lambda: all(runtime.snapshot.lines.get(n) for n in LINES), 30.0)
                await asyncio.sleep(seconds)
            finally:
                await runtime.stop()
    figures = {name: read_stats(path) for name, path in stats.items()}
    telegrams = {name: f["requests"] for name, f in figures.items()}
    injected = {
        name: (f["injected"]["late"], f["injected"]["garbage"]) for name, f in figures.items()
    }
    print(
        f"\n{seconds:g} s: telegrams {telegrams} (total {sum(telegrams.values())}),"
        f" late/garbage answers {injected}, false port losses {len(losses.seen)}"
        f" {[line for line, _ in losses.seen]}"
    )
    assert not losses.seen, losses.seen
    for name in LINES:
        late, garbage = injected[name]
        assert telegrams[name] > 20 * seconds, (name, telegrams)  # the line kept working
        assert late and garbage, (name, injected)  # under the faults that make stray input


async def test_three_faulty_pty_lines_on_a_busy_machine_lose_no_port(tmp_path: Path) -> None:
    await run_lines(tmp_path, *SHORT)


@pytest.mark.long
async def test_three_faulty_pty_lines_on_a_busy_machine_lose_no_port_in_a_minute(
    tmp_path: Path,
) -> None:
    await run_lines(tmp_path, *LONG)
