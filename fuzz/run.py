"""Run the atheris harnesses one after another and print what each executed and found.

    .venv/bin/python fuzz/run.py --seconds 60 [--target deframer] [--strict]

Each harness runs in its own process for N seconds (libFuzzer's
-max_total_time) with its corpus in var/fuzz/<target>/corpus and crash
inputs written to var/fuzz/<target>/. Exit status 1 when any target crashed.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
TARGETS = ("deframer", "pkw", "notation", "catalog", "fdl")
EXTRA_ARGS = {"catalog": ["-max_len=4096"]}

_STAT = re.compile(r"stat::number_of_executed_units:\s*(\d+)")
_DONE = re.compile(r"^#(\d+)\s+DONE", re.MULTILINE)
_RUNS = re.compile(r"^Done (\d+) runs", re.MULTILINE)
_LAST = re.compile(r"^#(\d+)\s", re.MULTILINE)
_ARTIFACT = re.compile(r"Test unit written to (\S+)")
_KNOWN = re.compile(r"^known finding (\S+):", re.MULTILINE)
_ERROR = re.compile(r"^([A-Za-z_][\w.]*(?:Error|Exception|Exit)\b.*)$", re.MULTILINE)


@dataclass
class Result:
    target: str
    seconds: float
    runs: int | None
    status: str
    known: list[str]
    artifact: str = ""
    error: str = ""


def executed_runs(log: str) -> int | None:
    """libFuzzer's count of executed inputs: final stats, else the DONE line, else the last #N."""
    for pattern in (_STAT, _DONE, _RUNS):
        found = pattern.findall(log)
        if found:
            return int(found[-1])
    found = _LAST.findall(log)
    return int(found[-1]) if found else None


def run_target(target: str, seconds: int, *, strict: bool) -> Result:
    work = ROOT / "var" / "fuzz" / target
    corpus = work / "corpus"
    corpus.mkdir(parents=True, exist_ok=True)
    log_path = work / "last.log"
    cmd = [
        sys.executable,
        str(HERE / f"fuzz_{target}.py"),
        f"-max_total_time={seconds}",
        "-timeout=10",
        "-rss_limit_mb=2048",
        "-print_final_stats=1",
        f"-artifact_prefix={work}/",
        *EXTRA_ARGS.get(target, []),
        str(corpus),
    ]
    env = dict(os.environ, PKWBUS_FUZZ_STRICT="1" if strict else "0")
    started = time.monotonic()
    with log_path.open("w") as log:
        proc = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, check=False)
    elapsed = time.monotonic() - started
    text = log_path.read_text(errors="replace")
    artifact = _ARTIFACT.findall(text)
    error = _ERROR.findall(text.split("== ERROR: libFuzzer", 1)[0])
    status = "ok" if proc.returncode == 0 else f"CRASH (exit {proc.returncode})"
    return Result(
        target,
        elapsed,
        executed_runs(text),
        status,
        sorted(set(_KNOWN.findall(text))),
        artifact[-1] if artifact else "",
        error[-1].strip() if error else "",
    )


def print_table(results: list[Result]) -> None:
    rows = [("target", "seconds", "inputs", "inputs/s", "result", "known findings seen")]
    for r in results:
        rate = f"{r.runs / r.seconds:.0f}" if r.runs and r.seconds else "-"
        runs = f"{r.runs:,}" if r.runs is not None else "?"
        rows.append((r.target, f"{r.seconds:.0f}", runs, rate, r.status, " ".join(r.known) or "-"))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip())
    for r in results:
        if r.artifact or r.error:
            print(f"\n{r.target}: crash input {r.artifact or '(none written)'}")
            if r.error:
                print(r.error)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=int, default=60, help="time per target (default 60)")
    parser.add_argument("--target", choices=TARGETS, action="append", help="only this target")
    parser.add_argument(
        "--strict", action="store_true", help="let known findings crash too (PKWBUS_FUZZ_STRICT)"
    )
    args = parser.parse_args(argv)
    results = []
    for target in args.target or TARGETS:
        print(f"fuzzing {target} for {args.seconds} s ...", file=sys.stderr, flush=True)
        results.append(run_target(target, args.seconds, strict=args.strict))
    print_table(results)
    return 0 if all(r.status == "ok" for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
