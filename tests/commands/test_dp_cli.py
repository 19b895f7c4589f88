"""`pkwbus read/write/describe/scan --protocol profibus` against simulated DP slaves on a pty
and on TCP (served from a thread of this process, so the wire can be recorded)."""

from __future__ import annotations

import asyncio
import json
import logging
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from pkwbus.cli import main
from pkwbus.protocol import pzd
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import DpSlave, NoAnswer, SlaveSetup
from pkwbus.sim import SimTiming
from pkwbus.sim.profibus.line import DpSimulator
from tests.master.wires.profibus.frame_log import FakeMaster, FrameLog, log_frames


class Served:
    """A simulator served on a pty or TCP by an event loop in a thread of its own."""

    def __init__(self, sim: DpSimulator, end: str) -> None:
        self.sim = sim
        self.wire: FrameLog = log_frames(sim)
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.tmp = tempfile.TemporaryDirectory()
        self.server: Any = self.call(self._serve(end))
        self.port: str = self.server.url if end == "tcp" else self.server.path

    async def _serve(self, end: str) -> Any:
        if end == "tcp":
            return await self.sim.serve_tcp("127.0.0.1", 0)
        return await self.sim.serve_pty(str(Path(self.tmp.name) / "ttyDP"))

    def call(self, coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(10)

    def close(self) -> None:
        self.call(self.server.close())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        self.tmp.cleanup()


@pytest.fixture(params=["pty", "tcp"])
def end(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def serve(end: str, dialect: str = "danfoss-pcv", **kw: Any) -> Served:
    kw.setdefault("timing", SimTiming(response_delay=0.0))
    return Served(DpSimulator([8, 9], dialect=dialect, seed=5, **kw), end)


@pytest.fixture
def danfoss(end: str) -> Iterator[Served]:
    served = serve(end)
    yield served
    served.close()
    served.wire.assert_never_took_control(served.sim.ppo.length, some=False)


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def dp(served: Served, *args: str, ident: bool = True) -> list[str]:
    ident_args = ["--ident", hex(served.sim.ident)] if ident else []
    return [
        "--port", served.port, "--protocol", "profibus", "--dialect", served.sim.dialect.name,
        "--slot-time", "20ms", *ident_args, *args,
    ]  # fmt: skip


def test_read_and_write_over_dp(capsys: pytest.CaptureFixture[str], danfoss: Served) -> None:
    code, out, err = run(capsys, "read", *dp(danfoss, "--address", "8", "16-13", "--json"))
    assert code == 0, err
    got = json.loads(out)
    assert got["pnu"] == 1613 and got["raw"] == danfoss.sim.drives[8].value(1613)
    code, out, err = run(capsys, "write", *dp(danfoss, "--address", "8", "3-41", "12.5"))
    assert code == 0, err
    assert danfoss.sim.drives[8].value(341) == 1250
    code, out, _ = run(capsys, "read", *dp(danfoss, "--address", "8", "15-30[2]", "--json"))
    assert code == 0 and json.loads(out)["index"] == 2
    assert danfoss.wire.set_prm()[(8, 2)] >= 1
    assert sum(s.clears for s in danfoss.sim.slaves.values()) >= 3  # Clear at each stop


@pytest.mark.parametrize(
    ("dialect", "parameter", "pnu", "index"),
    [("profidrive", "r2110[3]", 2110, 3), ("hitachi-sjpb", "947[1]", 947, 1)],
)
def test_other_dialects_array_and_page_index(
    capsys: pytest.CaptureFixture[str], end: str, dialect: str, parameter: str, pnu: int, index: int
) -> None:
    served = serve(end, dialect)
    try:
        code, out, err = run(capsys, "read", *dp(served, "--address", "9", parameter, "--json"))
        assert code == 0, err
        assert json.loads(out)["raw"] == served.sim.drives[9].value(pnu, index)
        code, _, err = run(
            capsys, "write", *dp(served, "--address", "9", "1120", "20.0", "--type", "f32")
        )
        assert code == 0, err
        assert served.sim.drives[9].value(1120) == 0x41A00000
    finally:
        served.close()
    served.wire.assert_never_took_control(served.sim.ppo.length)


def test_a_lagging_answer_and_a_rejection(capsys: pytest.CaptureFixture[str], end: str) -> None:
    served = serve(end, timing=SimTiming(response_delay=0.0, lag_telegrams=3))
    try:
        code, out, err = run(capsys, "read", *dp(served, "--address", "8", "3-42", "--json"))
        assert code == 0, err
        assert json.loads(out)["raw"] == served.sim.drives[8].value(342)
        code, out, err = run(capsys, "read", *dp(served, "--address", "8", "999", "--json"))
        assert code == 1
        assert json.loads(out)["error"] == {"kind": "rejected", "fault": 0, "text": "Illegal PNU"}
        assert "fault 0: Illegal PNU" in err
    finally:
        served.close()
    served.wire.assert_never_took_control(served.sim.ppo.length)
    assert served.sim.drives[8].lagged >= 3


def test_describe_over_dp(capsys: pytest.CaptureFixture[str], danfoss: Served) -> None:
    code, out, err = run(capsys, "describe", *dp(danfoss, "--address", "8", "3-41", "--json"))
    assert code == 0, err
    info = json.loads(out)
    # The PCV channel's PROFIdrive form (Danfoss VLT PROFIBUS manual MG.33.C4.02): size
    # index 4 (time) in the first byte, conversion -2 in the second; bit 9 clear.
    assert info["pnu"] == 341 and info["conversion_index"] == -2
    assert (info["unit_index"], info["unit"]) == (4, "s")
    assert info["read_only"] is False
    assert (info["min"], info["max"]) == (0.0, 3600.0)  # the danfoss-fc catalog's limits


def test_a_slave_owned_by_another_master_is_left_alone(
    capsys: pytest.CaptureFixture[str], danfoss: Served
) -> None:
    sim = danfoss.sim
    prm = dps.Parameters(sim.ident, dps.watchdog_factors(60.0))
    other = DpSlave(SlaveSetup(8, 1, prm, sim.ppo.cfg))
    for n in range(4):  # master 1 parametrises slave 8 with lock
        frame = other.poll(n * 0.01)
        assert frame is not None
        raw = sim.handle(fdl.encode(frame))
        other.feed(NoAnswer() if raw is None else fdl.decode(raw), n * 0.01)
    assert sim.slaves[8].owner == 1
    before = sim.drives[8].value(341)
    code, out, err = run(capsys, "write", *dp(danfoss, "--address", "8", "3-41", "7", "--json"))
    assert code == 3
    assert "owned by master 1" in err and json.loads(out)["error"]["kind"] == "locked"
    assert danfoss.wire.set_prm()[(8, 2)] == 0  # never parametrised by us
    assert not danfoss.wire.data_exchanges()
    assert sim.drives[8].value(341) == before and sim.slaves[8].owner == 1


def test_scan_is_a_live_list(capsys: pytest.CaptureFixture[str], danfoss: Served) -> None:
    code, out, err = run(capsys, "read", *dp(danfoss, "--address", "9", "16-13"))
    assert code == 0, err
    # Stations 1-20 at a 50 ms slot time: a slave's answer in time on a loaded machine (at
    # 3 ms for all 126, one was missed under load once).
    scan = ("--slot-time", "50ms", "--addresses", "1-20")
    code, out, err = run(capsys, "scan", *dp(danfoss, *scan, "--json", ident=False))
    assert code == 0, err
    found = {e["address"]: e for e in json.loads(out)}
    assert sorted(found) == [8, 9]
    assert found[8]["station_type"] == "slave" and found[8]["ident"] == danfoss.sim.ident
    assert found[8]["state"] == "wait_prm" and found[8]["master"] is None
    assert found[9]["state"] == "data_exchange" and found[9]["master"] == 2
    assert not [f for f in danfoss.wire.frames if f.dsap == dps.Service.SET_PRM and f.da == 8]
    code, out, _ = run(capsys, "scan", *dp(danfoss, *scan, ident=False))
    assert code == 0 and "2 found: 2 slaves" in out and "address 8: slave, ident 0x0402" in out


def test_trace_prints_decoded_frames(capsys: pytest.CaptureFixture[str], danfoss: Served) -> None:
    code, _, err = run(capsys, "read", *dp(danfoss, "--address", "8", "16-13", "--trace"))
    assert code == 0
    assert "tx SD2 da=8 sa=2 fc=0x6d dsap=60 ssap=62" in err  # the first Slave_Diag
    assert "rx SC" in err
    assert "tx SD2 da=127 sa=2 fc=0x46 dsap=58 ssap=62 data=02 00" in err  # Clear


def test_another_master_on_the_line_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    fake = FakeMaster()
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    asyncio.run_coroutine_threadsafe(fake.start(), loop).result(5)
    try:
        code, out, err = run(
            capsys, "read", "--port", fake.url, "--protocol", "profibus", "--ident", "0x0402",
            "--address", "8", "16-13", "--json",
        )  # fmt: skip
    finally:
        asyncio.run_coroutine_threadsafe(fake.close(), loop).result(5)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(5)
    assert code == 3
    assert "another master is active" in err and "nothing was sent" in err
    assert json.loads(out)["error"]["kind"] == "line_error"
    assert fake.received == b""


GSD_TEXT = """\
#Profibus_DP
Vendor_Name = "Test"
Ident_Number = 0x0402
User_Prm_Data_Len = 1
User_Prm_Data = 0x00
Module = "PPO 1" 0xF3,0xF1
EndModule
"""


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([], "--ident 0x0402"),
        (["--ident", "0x10000"], "16-bit"),
        (["--ident", "0x0402", "--cfg", "F3"], "PPO 1 has 12"),
        (["--ident", "0x0402", "--parity", "N"], "8E1"),
        (["--ident", "0x0402", "--dialect", "fc"], "not used over PROFIBUS"),
        (["--ident", "0x0402", "--retries", "9"], "at most 8"),
        (["--ident", "0x0402", "--ppo", "3", "--access", "pkw"], "PPO 3 has no PKW words"),
        (["--ident", "0x0402", "--axis", "1"], "--axis applies to --access ds47 only"),
        (["--ident", "0x0B6A", "--dialect", "hitachi-sjpb", "--access", "ds47"],
         "documents the PKW channel only"),
    ],
)  # fmt: skip
def test_bad_dp_options_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    code, _, err = run(
        capsys, "read", "--port", "/nonexistent/tty", "--protocol", "profibus",
        "--address", "8", *args, "16-13",
    )  # fmt: skip
    assert code == 2 and message in err


def test_a_scan_parametrises_nothing_so_takes_no_access(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(
        capsys, "scan", "--port", "/nonexistent/tty", "--protocol", "profibus", "--access", "ds47"
    )
    assert code == 2 and "the scan parametrises no slave" in err


def test_gsd_file(capsys: pytest.CaptureFixture[str], danfoss: Served, tmp_path: Path) -> None:
    good = tmp_path / "drive.gsd"
    good.write_text(GSD_TEXT)
    args = dp(danfoss, "--address", "8", "--gsd", str(good), "16-13", ident=False)
    code, _, err = run(capsys, "read", *args)
    assert code == 0, err
    bad = tmp_path / "bad.gsd"
    bad.write_text(GSD_TEXT.replace("Ident_Number = 0x0402", "Ident_Number = zz"))
    args = dp(danfoss, "--address", "8", "--gsd", str(bad), "16-13", ident=False)
    code, _, err = run(capsys, "read", *args)
    assert code == 2 and "GSD line 3" in err


VENDOR_SHAPED = Path(__file__).parents[1] / "protocol" / "profibus" / "gsd_files" / "mm4_like.gse"


def test_a_vendor_shaped_gsd_file_as_it_ships(capsys: pytest.CaptureFixture[str], end: str) -> None:
    """The MICROMASTER-4-like file (baud rate lines, DP-V1 keys, reference lines) with
    --gsd: the slave is parametrised from it and answers."""
    served = serve(end, "profidrive", catalog="siemens-g120")
    try:
        args = dp(served, "--address", "8", "--gsd", str(VENDOR_SHAPED), "r0021", ident=False)
        code, out, err = run(capsys, "read", *args)
        assert code == 0, err
        assert "r0021" in out
        prm = [f for f in served.wire.frames if f.dsap == dps.Service.SET_PRM]
        sent = dps.decode_parameters(prm[0].data)
        assert (sent.ident, sent.user_prm) == (0x80B5, bytes(3))  # the file's
    finally:
        served.close()


def test_cfg_given_beside_a_gsd_file_without_that_module(
    capsys: pytest.CaptureFixture[str], danfoss: Served, tmp_path: Path
) -> None:
    telegrams = tmp_path / "telegrams.gsd"
    telegrams.write_text(GSD_TEXT.replace('"PPO 1" 0xF3,0xF1', '"Telegram 1" 0x00,0xE1,0xD1'))
    args = dp(danfoss, "--address", "8", "--gsd", str(telegrams), "16-13", ident=False)
    code, _, err = run(capsys, "read", *args)
    assert code == 2 and "has no module for PPO 1 (modules: 'Telegram 1'); give --cfg" in err
    code, out, err = run(capsys, "read", *args[:-1], "--cfg", "F3 F1", "16-13")
    assert code == 0, err
    assert "16-13" in out


@pytest.mark.parametrize(
    ("extra", "args", "message"),
    [
        ("9.6_supp = 1\nMaxTsdr_9.6 = 60\n", ["--baudrate", "19200"],
         "the slave does not run at 19200 baud (the file names 9600): give --baudrate"),
        ("19.2_supp = 1\nMaxTsdr_19.2 = 600\n", ["--slot-time", "20ms"],
         "--slot-time: the slave may begin to answer 600 bit times (31.2 ms) after a request"),
    ],
)  # fmt: skip
def test_the_line_rate_and_slot_time_against_the_gsd_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, extra: str, args: list[str],
    message: str,
) -> None:  # fmt: skip
    path = tmp_path / "drive.gsd"
    path.write_text(GSD_TEXT + extra)
    code, _, err = run(
        capsys, "read", "--port", "/nonexistent/tty", "--protocol", "profibus",
        "--address", "8", "--gsd", str(path), *args, "16-13",
    )  # fmt: skip
    assert code == 2 and message in err, err


def test_read_write_and_describe_through_data_record_47(
    capsys: pytest.CaptureFixture[str], end: str
) -> None:
    # A PPO-3 slave has no PKW words: its parameters go through data record 47 (DP-V1).
    served = serve(end, "profidrive", ppo_number=3, catalog="siemens-g120", dpv1=True,
                   not_ready=2)  # fmt: skip
    try:
        code, out, err = run(capsys, "read", *dp(served, "--ppo", "3", "--address", "8", "p1120",
                                                 "--json"))  # fmt: skip
        assert code == 0, err
        got = json.loads(out)
        assert got["raw"] == served.sim.drives[8].value(1120)
        code, out, err = run(
            capsys, "write", *dp(served, "--ppo", "3", "--address", "8", "p1121", "12.15")
        )
        assert code == 0, err
        assert abs(served.sim.drives[8].params.number(1121) - 12.15) < 1e-5
        assert served.sim.drives[9].params.number(1121) != served.sim.drives[8].params.number(1121)
        code, out, err = run(capsys, "describe", *dp(served, "--ppo", "3", "--address", "8",
                                                     "p1121"))  # fmt: skip
        assert code == 0, err
        assert served.sim.slaves[8].record_writes >= 3
        # An unknown parameter: the drive's error number, in words.
        code, out, err = run(capsys, "read", *dp(served, "--ppo", "3", "--address", "8", "r9999"))
        assert code != 0
        assert "Illegal parameter number" in out + err
        # Without a catalog (nor --type) the drive's own answer names the type: a read
        # first, then the write as FloatingPoint.
        untyped = ("--ppo", "3", "--address", "8", "p1121", "7.25", "--catalog", "none")
        code, out, err = run(capsys, "write", *dp(served, *untyped))
        assert code == 0, err
        assert served.sim.drives[8].params.number(1121) == 7.25
        # A change to EEPROM does not travel in the SINAMICS data set 47: refused, unsent.
        before = served.sim.slaves[8].record_writes
        code, out, err = run(capsys, "write", *dp(served, "--ppo", "3", "--address", "8",
                                                  "p1121", "3.0", "--store", "eeprom"))  # fmt: skip
        assert code == 2 and "RAM only" in err
        assert served.sim.slaves[8].record_writes == before
    finally:
        served.close()
    # Every Data_Exchange of PPO 3 (no PKW words) began with a control word of 0.
    ctws = [int.from_bytes(f.data[:2], "big") for f in served.wire.data_exchanges()]
    assert ctws and all(w == pzd.MONITORING_CTW for w in ctws)


@pytest.mark.parametrize(
    ("given", "says"),
    [
        (["--ident", "0x9999"], "slave 8 refuses its parameters (Prm_Fault): its ident number is"),
        (["--ppo", "3"], "slave 8 refuses its configuration (Cfg_Fault)"),
    ],
    ids=["ident", "ppo"],
)
def test_a_slave_that_refuses_what_it_is_sent_is_named_once(
    capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture, given: list[str],
    says: str,
) -> None:  # fmt: skip
    """A slave that refuses its parameters or configuration is parametrised again every
    cycle: the log says so once, not every cycle, and the command's message says why from
    the slave's diagnosis, not only that the time ran out."""
    caplog.set_level(logging.WARNING)
    served = serve("tcp")
    try:
        ident = given if given[0] == "--ident" else ["--ident", hex(served.sim.ident)]
        args = dp(served, "--address", "8", "16-13", ident=False)
        code, _, err = run(capsys, "read", *ident, *[g for g in given if g not in ident], *args)
    finally:
        served.close()
    assert code == 3, err
    assert says in err, err
    if given[0] == "--ident":
        assert f"{served.sim.ident:#06x}, not 0x9999" in err
    again = [r for r in caplog.records if "parametrised again" in r.getMessage()]
    assert len(again) == 1, [r.getMessage() for r in again]
    assert served.wire.set_prm()[(8, 2)] > 3  # parametrised over and over meanwhile


def test_a_scan_whose_port_cannot_be_opened_exits_4(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "scan", "--port", "/nonexistent/tty", "--protocol", "profibus")
    assert code == 4 and "/nonexistent/tty" in err
