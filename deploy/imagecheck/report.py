"""The timed steps, their ok or FAIL, and the closing verdict."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator

results: list[str] = []
failed: list[str] = []
skipped: list[str] = []


class CheckFailed(Exception):
    pass


def say(msg: str) -> None:
    print(msg, flush=True)


@contextlib.contextmanager
def step(name: str) -> Iterator[None]:
    """One timed step: ok, or FAIL with the reason; a failure does not stop the others."""
    start = time.monotonic()
    say(f"--- {name}")
    try:
        yield
    except CheckFailed as exc:
        took = time.monotonic() - start
        failed.append(name)
        results.append(f"FAIL  {name} ({took:.0f}s)")
        say(f"FAIL  {name}: {exc}")
    else:
        took = time.monotonic() - start
        results.append(f"ok    {name} ({took:.0f}s)")
        say(f"ok    {name} ({took:.1f}s)")


def expect(cond: bool, msg: str) -> None:
    if not cond:
        raise CheckFailed(msg)


def exit_code() -> int:
    return 1 if failed else 0


def summary(started: float) -> None:
    """Every step's result, then the verdict with the time since ``started`` (monotonic)."""
    say("\n".join(results))
    total = time.monotonic() - started
    verdict = f"FAILED: {', '.join(failed)}" if failed else "all checks passed"
    if skipped:
        verdict += f"; SKIPPED: {skipped[0]}"
    say(f"deploy/image-check: {verdict} ({total:.0f}s)")
