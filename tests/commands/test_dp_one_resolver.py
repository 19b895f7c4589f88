"""One DP resolver: `pkwbus read --gsd` and the service parametrise the same slave with the
same Set_Prm (ident, watchdog, user parameters), measured at the simulated slave: the slot
time and the watchdog are computed in one place (``dp_settings``)."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from pkwbus.catalog.dp_settings import watchdog
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from tests.commands.test_dp_cli import Served, run, serve
from tests.master.conftest import until

GSD = """\
#Profibus_DP
Vendor_Name = "Test"
Ident_Number = 0x0402
19.2_supp = 1
MaxTsdr_19.2 = 120
User_Prm_Data_Len = 2
User_Prm_Data = 0x00,0x05
Module = "PPO 1" 0xF3,0xF1
EndModule
"""


def sent_set_prm(served: Served, address: int) -> dps.Parameters:
    frames = [f for f in served.wire.frames if f.dsap == dps.Service.SET_PRM and f.da == address]
    assert frames, "the slave was parametrised"
    return dps.decode_parameters(frames[0].data)


def from_the_command(capsys: pytest.CaptureFixture[str], gsd: Path) -> dps.Parameters:
    served = serve("tcp")
    try:
        code, _, err = run(
            capsys, "read", "--port", served.port, "--protocol", "profibus", "--dialect",
            "danfoss-pcv", "--gsd", str(gsd), "--baudrate", "19200", "--retries", "2",
            "--address", "8", "16-13",
        )  # fmt: skip
        assert code == 0, err
        return sent_set_prm(served, 8)
    finally:
        served.close()


def from_the_service(gsd: Path) -> dps.Parameters:
    served = serve("tcp")
    text = f"""
audit_db: ":memory:"
lines:
  - name: dp
    port: {served.port}
    protocol: profibus
    baudrate: 19200
    retries: 2
    alarms: off
    counters: off
    settings: off
    drives:
      - {{name: mixer, address: 8, dialect: danfoss-pcv, gsd: "{gsd}", catalog: danfoss-fc,
          poll: [{{parameter: "16-13", every: 100ms}}]}}
"""

    async def parametrise() -> None:
        runtime = await build_runtime(parse_config(text, environ={}))
        await runtime.start()
        try:
            await until(lambda: served.wire.set_prm()[(8, 2)] >= 1, timeout=20)
        finally:
            await runtime.stop()

    try:
        asyncio.run(parametrise())
        return sent_set_prm(served, 8)
    finally:
        served.close()


def test_the_command_and_the_service_send_the_same_set_prm(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    gsd = tmp_path / "drive.gsd"
    gsd.write_text(GSD, encoding="utf-8")
    command, service = from_the_command(capsys, gsd), from_the_service(gsd)
    assert command == service
    assert (command.ident, command.user_prm) == (0x0402, bytes([0x00, 0x05]))  # the file's
    assert command.watchdog_seconds is not None and command.watchdog_seconds >= 1.0


def test_the_watchdog_grows_with_the_slaves_the_master_cycles_through() -> None:
    slot = 0.03
    one, many = watchdog(slot, 2, 1), watchdog(slot, 2, 30)
    assert one == 1.0, "at least a second"
    assert many == pytest.approx(10 * slot * 3 * 30), "ten worst-case cycles of 30 slaves"
    assert watchdog(slot, 2, 30, given=5.0) == 5.0
