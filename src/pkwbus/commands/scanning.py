"""What the scans of FC/USS lines and of PROFIBUS lines share: the ``--addresses`` option
and the progress line on a terminal.

Raises :class:`~pkwbus.commands.common.CommandError` (exit 2) for bad ``--addresses``.
"""

from __future__ import annotations

from typing import TextIO

from pkwbus import limits
from pkwbus.commands.common import CommandError, Exit

__all__ = ["Progress", "parse_addresses"]


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
