"""Shared by the atheris harnesses: seed corpora and the register of known findings.

A known finding is a bug already reported (docs/fuzzing.md, and a strict xfail
test in tests/protocol/test_fuzz_properties.py). By default a harness tolerates
it, says so once on stderr and keeps fuzzing, so a run finds the *next* bug.
Set ``PKWBUS_FUZZ_STRICT=1`` to make known findings crash like new ones.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

STRICT = os.environ.get("PKWBUS_FUZZ_STRICT", "") not in ("", "0")


@dataclass(frozen=True)
class Known:
    """A reported bug: its id in docs/fuzzing.md and a narrow test for its exception."""

    ident: str
    matches: Callable[[BaseException], bool]


_seen: set[str] = set()


def tolerate(exc: BaseException, known: Iterable[Known]) -> None:
    """Swallow ``exc`` when it is a known finding (and not strict); re-raise anything else."""
    if not STRICT:
        for finding in known:
            if finding.matches(exc):
                if finding.ident not in _seen:
                    _seen.add(finding.ident)
                    print(f"known finding {finding.ident}: {exc!r:.200}", file=sys.stderr)
                return
    raise exc


def write_seeds(seeds: Iterable[bytes], argv: list[str] | None = None) -> None:
    """Put ``seeds`` into the first corpus directory on the command line when it is empty."""
    args = sys.argv[1:] if argv is None else argv
    dirs = [Path(a) for a in args if not a.startswith("-")]
    if not dirs:
        return
    corpus = dirs[0]
    corpus.mkdir(parents=True, exist_ok=True)
    if any(corpus.iterdir()):
        return
    for n, seed in enumerate(seeds):
        (corpus / f"seed-{n:03d}").write_bytes(seed)
