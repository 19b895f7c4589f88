"""A DP line where another master passes the token, under the runner: nothing is sent, the
port is reopened at a back-off that grows to its cap (not at the first back-off each time:
each opening succeeds, and is refused at once), and the outage is told once in the log."""

from __future__ import annotations

import asyncio
import logging

import pytest

from pkwbus.link import PortSettings
from pkwbus.master.runner import LineRunner
from pkwbus.master.wires.profibus.port import FdlPort
from pkwbus.master.wires.profibus.wire import CycleWire
from tests.master.wires.profibus.frame_log import fake_master

MASTER = 2


async def test_a_line_another_master_runs_backs_off_to_the_cap_and_is_told_once(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    caplog.set_level(logging.DEBUG, logger="pkwbus.master.runner")
    async with fake_master() as fake:
        settings = PortSettings(fake.url, baudrate=19200, reopen_initial=0.01, reopen_cap=0.04)
        port = FdlPort(settings, MASTER, slot_time=0.02, clear_on_close=True)
        runner = LineRunner("dp", port, CycleWire([], name="dp"), [])
        reconnect = port.link.reconnect
        waits: list[float] = []  # each failure's back-off, from the failure's own time
        failed = reconnect.failed

        def record(reason: str, now: float) -> None:
            failed(reason, now)
            waits.append(reconnect.next_attempt - now)

        monkeypatch.setattr(reconnect, "failed", record)
        task = asyncio.create_task(runner.run())
        try:
            loop = asyncio.get_running_loop()
            end = loop.time() + 60.0  # generous: a loaded machine
            while len(waits) < 6 and loop.time() < end:
                await asyncio.sleep(0.01)
        finally:
            runner.stop()
            await asyncio.wait_for(task, 30.0)
        assert fake.received == b"", "nothing is sent on a line another master runs"
    assert waits[:6] == pytest.approx([0.01, 0.02, 0.04, 0.04, 0.04, 0.04])
    said = [r for r in caplog.records if r.levelno >= logging.INFO]
    refused = [r for r in said if "another master is active" in r.getMessage()]
    opened = [r for r in said if r.getMessage().startswith("line dp: port ")]
    # Refused (error) and given up (warning) once; open at the start and once again.
    assert [r.levelno for r in refused] == [logging.ERROR, logging.WARNING]
    assert len(opened) == 2
    quiet = [r for r in caplog.records if r.levelno == logging.DEBUG]
    assert sum("another master is active" in r.getMessage() for r in quiet) >= 4
