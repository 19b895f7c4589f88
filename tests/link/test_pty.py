"""A pseudo-terminal is opened with the one parity it keeps; everything else as configured."""

from __future__ import annotations

import os
import sys
import termios

import pytest

from pkwbus.link import Link, LinkState, PortSettings
from pkwbus.link.serialport import describe_error as _reason
from pkwbus.link.serialport import is_pty
from pkwbus.link.serialport import open_port as _open_port

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux ptys")


def test_ptys_are_told_from_real_ports_and_urls(pty_path: str) -> None:
    assert is_pty(pty_path) and is_pty(os.path.realpath(pty_path))
    for other in ("/dev/null", "/nonexistent/tty", "loop://", "socket://127.0.0.1:1"):
        assert not is_pty(other)


@pytest.mark.parametrize("parity", ["E", "O", "N"])
def test_a_pty_opens_again_and_again_with_any_parity(pty_path: str, parity: str) -> None:
    for baudrate in (9600, 9600, 19200, 19200, 115200):
        port = _open_port(PortSettings(pty_path, baudrate=baudrate, parity=parity))
        assert (port.parity, port.baudrate) == ("N", baudrate)
        port.close()


@pytest.mark.parametrize("parity", ["E", "O", "N"])
def test_other_ports_get_the_configured_parity(parity: str) -> None:
    port = _open_port(PortSettings("loop://", baudrate=19200, parity=parity, stopbits=2))
    assert (port.parity, port.baudrate, port.stopbits) == (parity, 19200, 2)
    port.close()


async def test_a_link_reopens_a_pty_with_parity_e(pty_path: str) -> None:
    for _ in range(3):
        link = Link(PortSettings(pty_path, baudrate=19200, parity="E"))
        await link.open()
        assert link.state is LinkState.OPEN
        await link.close()


def test_a_termios_error_reads_as_the_systems_words() -> None:
    assert _reason(termios.error(22, "Invalid argument")) == os.strerror(22)
