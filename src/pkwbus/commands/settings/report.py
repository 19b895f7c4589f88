"""What `pkwbus restore` prints and the exit code it ends with.

The plan (each write, from the present value to the backup's), the skipped settings
with their reasons, and each write's outcome; ``--json``: one object with the keys of
the service's restore answer (``drive``, ``dry_run``, ``plan``, ``skipped``,
``results``) and the drive's ``identity``. Exit codes (README.md's table):

- 0: every planned write done and read back (or a dry run, or nothing to write);
- 1: the drive refused a write, or it could not be sent (the others were made);
- 2: the backup is of another drive type or dialect: nothing written (``--force``);
- 3: a write or its read-back got no answer: the restore stopped there;
- 5: a read-back gave another value than the one written: the restore stopped there.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from typing import Any

from pkwbus.commands.common import Exit, emit_json
from pkwbus.service.history.backup import Backup, Planned, Skipped

__all__ = ["Restored", "exit_code", "report"]

_NO_ANSWER = frozenset({"unverified", "timeout", "line_error"})


@dataclass
class Restored:
    """A restore planned (and, unless a dry run, done): ``results`` one per planned write
    in order; ``other`` why the backup is not this drive's (then nothing is planned)."""

    backup: Backup
    identity: str | None
    plan: list[Planned]
    skipped: list[Skipped]
    dry_run: bool
    other: str | None = None
    results: list[dict[str, Any]] = field(default_factory=list)


def exit_code(done: Restored) -> Exit:
    if done.other is not None:
        return Exit.BAD_INPUT
    outcomes = {r["outcome"] for r in done.results}
    if done.dry_run and "invalid" in outcomes:
        return Exit.BAD_INPUT  # a write that could not go out: nothing was sent
    if "mismatch" in outcomes:
        return Exit.MISMATCH
    if outcomes & _NO_ANSWER:
        return Exit.NO_ANSWER
    if outcomes - {"ok", "dry_run"}:
        return Exit.REJECTED
    return Exit.OK


def report(args: argparse.Namespace, done: Restored) -> None:
    problem = _problem(done)
    if problem is not None:
        print(f"pkwbus: {problem}", file=sys.stderr)
    if args.json:
        emit_json({
            "drive": done.backup.drive,
            "identity": done.identity,
            "dry_run": done.dry_run,
            "plan": [p.as_dict() for p in done.plan],
            "skipped": [s.as_dict() for s in done.skipped],
            "results": done.results,
        })  # fmt: skip
        return
    units = {(s.parameter, s.index): s.unit for s in done.backup.settings}
    b = done.backup
    print(f"backup of {b.drive} ({b.identity or 'identity unknown'}), {b.time or 'undated'}:")
    print(f"  {len(b.settings)} setting(s); this drive: {done.identity or 'identity unknown'}")
    print(f"plan: {len(done.plan)} write(s)")
    for p in done.plan:
        unit = units.get((p.parameter, p.index), "")
        print(f"  {_name(p.parameter, p.index)}: {_shown(p.old, unit)} -> {_shown(p.new, unit)}")
    if done.other is not None:
        print(f"skipped: all {len(done.skipped)}: {done.other}")
    elif done.skipped:
        print(f"skipped: {len(done.skipped)}")
        for s in done.skipped:
            print(f"  {_name(s.parameter, s.index)}: {s.why}")
    if done.dry_run:
        for r in done.results:
            if r["outcome"] != "dry_run":
                print(f"  {_name(r['parameter'], r['index'])}: {_result(r)}")
        print("dry run: nothing written")
        return
    if done.results:
        print("writes:")
    for r in done.results:
        print(f"  {_name(r['parameter'], r['index'])}: {_result(r)}")
    if done.other is None:
        print(_summary(done))


def _problem(done: Restored) -> str | None:
    """One line for stderr when the restore did not do all it planned."""
    if done.other is not None:
        return f"{done.other}: nothing written (--force restores it)"
    stop = next((r for r in done.results if r["outcome"] in _NO_ANSWER | {"mismatch"}), None)
    if stop is not None:
        rest = sum(r["outcome"] == "not_sent" for r in done.results)
        where = _name(stop["parameter"], stop["index"])
        why = f"{stop['outcome']}: {stop['detail']}"
        return f"the restore stopped at {where} ({why}); {rest} not sent"
    failed = [
        f"{_name(r['parameter'], r['index'])} ({r['outcome']})"
        for r in done.results
        if r["outcome"] not in ("ok", "dry_run")
    ]
    if failed:
        return f"{len(failed)} write(s) not made: {', '.join(failed)}"
    return None


def _summary(done: Restored) -> str:
    if not done.plan:
        return "nothing to write: the drive holds the backup's values"
    ok = sum(r["outcome"] == "ok" for r in done.results)
    return f"restored {ok} of {len(done.plan)} planned write(s)"


def _result(r: dict[str, Any]) -> str:
    outcome = r["outcome"]
    if outcome == "ok":
        return "written, read back"
    text = f"{outcome.replace('_', ' ')}: {r.get('detail', '')}"
    if r.get("when_stopped"):
        text += " (only while the motor is stopped)"
    return text


def _name(parameter: str, index: int) -> str:
    return f"{parameter}[{index}]" if index else parameter


def _shown(value: object, unit: str) -> str:
    if value is None:
        return "?"
    return f"{value} {unit}".strip()
