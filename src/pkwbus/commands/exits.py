"""The exit codes of ``pkwbus``, as README.md lists them."""

from __future__ import annotations

import enum

__all__ = ["Exit"]


class Exit(enum.IntEnum):
    """The exit codes of ``pkwbus``, as README.md lists them."""

    OK = 0
    REJECTED = 1
    BAD_INPUT = 2
    NO_ANSWER = 3
    PORT = 4
    MISMATCH = 5  # the drive acknowledged a write with another value than the one sent
    BUG = 70  # EX_SOFTWARE: an exception pkwbus did not expect
    INTERRUPTED = 130  # 128 + SIGINT
    PIPE_CLOSED = 141  # 128 + SIGPIPE: the reader of the output went away (| head)
