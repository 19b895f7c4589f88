"""What the scans of FC/USS lines and of PROFIBUS lines share: the ``--addresses`` option,
the progress line on a terminal and the end: the summary and the exit status.

Raises :class:`~pkwbus.commands.common.CommandError` (exit 2) for bad ``--addresses``.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

from pkwbus.commands.common import CommandError, Exit, emit_json
from pkwbus.notation import limits

__all__ = ["Progress", "parse_addresses", "report"]


def parse_addresses(text: str, low: int, high: int) -> list[int]:
    """``1-126`` or ``1,2,5-9``, each address ``low``-``high`` (the protocol's range)."""
    try:
        found = limits.parse_addresses(text, low, high)
    except ValueError as exc:
        raise CommandError(f"--addresses: {exc}", Exit.BAD_INPUT) from None
    if not found:
        raise CommandError("--addresses: no address given", Exit.BAD_INPUT)
    return found


class Progress:
    """One line on a terminal, rewritten in place; nothing when it is not one."""

    def __init__(self, stream: TextIO, enabled: bool) -> None:
        self.stream = stream
        self.enabled = enabled
        self.shown = False

    def show(self, text: str) -> None:
        if self.enabled:
            self.stream.write(f"\r\x1b[K{text}")
            self.stream.flush()
            self.shown = True

    def clear(self) -> None:
        if self.shown:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self.shown = False


def report(as_json: bool, found: list[dict[str, Any]], summary: str) -> int:
    """The end of a scan: with ``--json`` the drives found, then the summary (on stderr
    when none answered: exit 3). Without it each drive was printed as it was found."""
    if as_json:
        emit_json(found)
        if not found:
            print(summary, file=sys.stderr)
    else:
        print(summary, file=sys.stdout if found else sys.stderr)
    return Exit.OK if found else Exit.NO_ANSWER
