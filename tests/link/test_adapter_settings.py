"""Adapter settings of a line: low latency (refused: one warning, the line runs) and kernel
RS-485 mode (refused: a clear error at open naming the setting)."""

from __future__ import annotations

import logging
import os
import sys
from typing import Any

import pytest

from pkwbus.link import Link, LinkState, PortError, PortSettings
from pkwbus.link.serialport import apply_adapter_settings
from pkwbus.link.serialport import open_port as _open_port
from pkwbus.link.settings import Rs485Mode
from pkwbus.service.config.resolved import port_for as _line
from tests.service.config.test_config import parse, problems_of

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux ptys")


class FakeSerial:
    """What the settings touch of a pyserial port: records them as a real driver would."""

    def __init__(self) -> None:
        self.rs485_mode: Any = None
        self.low_latency: bool | None = None

    def set_low_latency_mode(self, on: bool) -> None:
        self.low_latency = on


def test_settings_are_applied_to_the_port() -> None:
    port = FakeSerial()
    mode = Rs485Mode(
        rts_level_for_tx=False, rts_level_for_rx=True, delay_before_tx=0.002, delay_before_rx=0.001
    )
    apply_adapter_settings(port, PortSettings("/dev/ttyS1", low_latency=True, rs485=mode))
    assert port.low_latency is True
    applied = port.rs485_mode
    assert (applied.rts_level_for_tx, applied.rts_level_for_rx) == (False, True)
    assert (applied.delay_before_tx, applied.delay_before_rx) == (0.002, 0.001)
    assert applied.loopback is False


def test_nothing_is_applied_unless_asked() -> None:
    port = FakeSerial()
    apply_adapter_settings(port, PortSettings("/dev/ttyS1"))
    assert port.low_latency is None and port.rs485_mode is None


@linux
async def test_rs485_refused_by_a_pty_is_an_error_naming_the_setting(pty_path: str) -> None:
    link = Link(PortSettings(pty_path, rs485=Rs485Mode()))
    with pytest.raises(PortError) as caught:
        await link.open()
    message = str(caught.value)
    assert message == (
        f"cannot open {pty_path}: rs485: the driver refuses kernel RS-485 mode ({os.strerror(25)})"
    )
    assert link.state is LinkState.FAILED


@linux
def test_a_refused_rs485_mode_leaves_no_port_open(pty_path: str) -> None:
    before = set(os.listdir("/proc/self/fd"))
    for _ in range(3):
        with pytest.raises(Exception, match="rs485"):
            _open_port(PortSettings(pty_path, rs485=Rs485Mode()))
    assert set(os.listdir("/proc/self/fd")) <= before


@linux
async def test_low_latency_refused_by_a_pty_warns_once_and_the_line_runs(
    pty_path: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, "pkwbus.link.port")
    for _ in range(3):  # a reopen does not repeat the warning
        link = Link(PortSettings(pty_path, low_latency=True))
        await link.open()
        assert link.state is LinkState.OPEN
        await link.close()
    warnings = [r.getMessage() for r in caplog.records if "low_latency" in r.getMessage()]
    assert warnings == [
        f"low_latency: {pty_path} does not take it ({os.strerror(25)});"
        " the line runs at its own latency"
    ]


def test_low_latency_on_a_url_without_it_warns(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, "pkwbus.link.port")
    port = _open_port(PortSettings("loop://", low_latency=True))
    try:
        assert port.is_open
    finally:
        port.close()
    assert "low_latency: loop:// does not take it (it has no such setting)" in caplog.text


LINE = """
lines:
  - name: l1
    port: {port}
    protocol: fc
    baudrate: 19200
{extra}    drives:
      - {{name: a, address: 1}}
"""


def test_config_carries_the_settings_to_the_port() -> None:
    extra = (
        "    low_latency: true\n"
        "    rs485: {rts_level_for_tx: true, delay_before_tx: 2ms, delay_before_rx: 0}\n"
    )
    line = parse(LINE.format(port="/dev/ttyS1", extra=extra)).lines[0]
    settings = _line(line, line.port).link.settings
    assert settings.low_latency is True
    assert settings.rs485 == Rs485Mode(True, False, 0.002, 0.0)
    plain = parse(LINE.format(port="/dev/ttyS1", extra="")).lines[0]
    assert _line(plain, plain.port).link.settings.rs485 is None
    assert _line(plain, plain.port).link.settings.low_latency is False


@pytest.mark.parametrize(
    ("extra", "problem"),
    [
        ("    rs485: {delay_before_tx: 0.5ms}\n", "whole milliseconds"),
        ("    rs485: {delay_before_rx: 1s}\n", "too long for an RS-485 RTS delay (0 to 100 ms)"),
        ("    rs485: {rts_level_for_tx: 1}\n", "rs485.rts_level_for_tx"),
        ("    rs485: {loopback: true}\n", "rs485.loopback"),
        ("    low_latency: yes please\n", "low_latency"),
    ],
)
def test_bad_adapter_settings_are_named(extra: str, problem: str) -> None:
    problems = problems_of(LINE.format(port="/dev/ttyS1", extra=extra))
    assert len(problems) == 1 and problem in problems[0], problems


def test_rs485_on_a_network_port_is_refused() -> None:
    extra = "    rs485: {rts_level_for_tx: true}\n"
    (problem,) = problems_of(LINE.format(port="socket://gw:4001", extra=extra))
    assert problem.startswith("lines[0].rs485: ")
    assert "applies to a serial device" in problem
