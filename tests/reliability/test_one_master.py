"""One master per RS-485 line on every path: a configuration that names one device twice
is refused, and a port that a pkwbus process holds is refused to any other, with nothing
sent; the process's own reopen is not blocked by itself."""

from __future__ import annotations

import asyncio
import os
import sys
from pathlib import Path

import pytest

from pkwbus.cli import main
from pkwbus.link import Link, LinkState, PortBusy, PortSettings, same_line
from pkwbus.sim import SimTiming, Simulator
from tests.reliability.helpers import record_wire
from tests.reliability.service import start_run
from tests.service.http.conftest import line_yaml


def drives(*addresses: int) -> list[dict[str, object]]:
    return [
        {"name": f"fan{a}", "address": a, "catalog": "danfoss-fc", "poll": [("16-13", "50ms")]}
        for a in addresses
    ]


async def test_a_line_repeated_through_a_symlink_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.001))
    wire = record_wire(sim)
    tty = str(tmp_path / "ttyA")
    server = await sim.serve_pty(tty)
    try:
        by_id = tmp_path / "usb-FTDI_USB-RS485-if00-port0"
        by_id.symlink_to(os.path.realpath(tty))  # as /dev/serial/by-id/... names a device
        config = tmp_path / "pkwbus.yaml"
        config.write_text(
            "lines:\n"
            + line_yaml("first", tty, "fc", drives(1))
            + "\n"
            + line_yaml("second", str(by_id), "fc", drives(2))
            + "\n"
        )
        assert same_line(tty) == same_line(str(by_id))
        for command in (["check-config", str(config)], ["run", "--config", str(config)]):
            assert main(command) == 2
            err = capsys.readouterr().err
            assert "lines[1].port: " in err and "the same device as lines[0] (first)" in err
            assert "Traceback" not in err
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "pkwbus", "check-config", str(config),
            stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        _, err_bytes = await proc.communicate()
        assert proc.returncode == 2 and b"the same device as lines[0]" in err_bytes
        assert not wire.requests  # refused before any port was opened
    finally:
        await server.close()


@pytest.mark.parametrize(
    ("one", "other", "same"),
    [
        ("socket://gw:4001", "socket://GW:4001", True),
        ("socket://gw:4001", "rfc2217://gw:4001", True),
        ("socket://gw:4001", "socket://gw:4002", False),
        ("/dev/nonexistent-a", "/dev/nonexistent-a", True),
        ("/dev/nonexistent-a", "/dev/nonexistent-b", False),
        ("loop://", "loop://?logging=debug", False),
    ],
)
def test_which_ports_name_one_line(one: str, other: str, same: bool) -> None:
    assert (same_line(one) == same_line(other)) is same


async def test_a_port_a_link_holds_is_refused_to_another_and_its_own_reopen_is_not(
    tmp_path: Path,
) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.001))
    tty = str(tmp_path / "ttyB")
    server = await sim.serve_pty(tty)
    first, second = Link(PortSettings(tty, 115200)), Link(PortSettings(tty, 115200))
    try:
        await first.open()
        with pytest.raises(PortBusy, match=f"cannot open {tty}: in use by another process"):
            await second.open()
        assert second.state is LinkState.FAILED
        first.abort("lost")  # its own loss: the lock goes with it
        await first.open()
        assert first.is_open
        await first.close()
        await second.open()  # free again
        assert second.is_open
    finally:
        await first.close()
        await second.close()
        await server.close()


async def test_pkwbus_read_is_refused_on_a_port_pkwbus_run_holds(tmp_path: Path) -> None:
    """Two masters on one line: the second one is refused (exit 4) and says by whom, and no
    telegram of it reaches the drives."""
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.001), catalog="danfoss-fc")
    wire = record_wire(sim)
    tty = str(tmp_path / "ttyC")
    server = await sim.serve_pty(tty)
    config = tmp_path / "pkwbus.yaml"
    config.write_text("lines:\n" + line_yaml("line1", tty, "fc", drives(1)) + "\n")
    proc, _ = await start_run(["run", "--config", str(config)], tmp_path / "run.log")
    try:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 30
        while wire.requests[1] < 3:  # the service polls drive 1
            assert loop.time() < deadline, (tmp_path / "run.log").read_text()
            await asyncio.sleep(0.05)
        read = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "pkwbus", "read", "--port", tty, "--protocol", "fc",
            "--baudrate", "115200", "--address", "2", "16-13",
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        out, err = await asyncio.wait_for(read.communicate(), 60)
        text = err.decode()
        assert read.returncode == 4, text
        assert f"cannot open {tty}: in use by another process (pid {proc.pid}: " in text
        assert "pkwbus run --config" in text  # who holds it
        assert text.rstrip().endswith("nothing was sent")
        assert "Traceback" not in text and out == b""
        assert wire.requests[2] == 0  # nothing of the second master reached the line
        assert proc.returncode is None  # the service goes on
        polled = wire.requests[1]
        while wire.requests[1] < polled + 3:
            assert loop.time() < deadline + 30
            await asyncio.sleep(0.05)
    finally:
        proc.terminate()
        await proc.wait()
        await server.close()
