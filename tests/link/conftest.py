"""A pty reached by a symlink, for the link's tests."""

from __future__ import annotations

import os
import tempfile
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest


@pytest.fixture
def pty_path() -> Iterator[str]:
    """A pty whose other end stays open (as the simulator keeps it), reached by a symlink."""
    controller, follower = os.openpty()
    tty.setraw(follower)
    with tempfile.TemporaryDirectory() as tmp:
        link = Path(tmp) / "ttyX"
        link.symlink_to(os.ttyname(follower))
        try:
            yield str(link)
        finally:
            os.close(controller)
            os.close(follower)
