"""A reload on a PROFIBUS DP line, measured at the simulated slaves: a change of a slave's
polls applies without parametrising anything again (no Set_Prm, the port stays open); a
slave added changes the cycle and its watchdog, so the line is opened again alone and every
slave parametrised afresh; a line of another bus changed beside it leaves it alone."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass
from pathlib import Path

from prometheus_client import generate_latest

from pkwbus.protocol.profibus.dp.services import Service
from pkwbus.service.assembly.build import Parts, assemble
from pkwbus.service.assembly.history import remember
from pkwbus.service.assembly.reload import Reloader
from pkwbus.service.config import Config, parse_config
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.profibus.line import DpSimulator
from pkwbus.sim.serving.ends import TcpEnd
from tests.master.wires.profibus.frame_log import FrameLog, log_frames

NAMES = {8: "mixer", 9: "pump", 10: "fan"}


def slave(address: int, polls: list[str]) -> str:
    listed = ", ".join(f'{{parameter: "{p}", every: 100ms}}' for p in polls)
    return f"""      - name: {NAMES[address]}
        address: {address}
        dialect: danfoss-pcv
        ident: 0x0402
        catalog: danfoss-fc
        poll: [{listed}]"""


def config_text(dp_url: str, fc_url: str, slaves: list[str], fc_timeout: str = "250ms") -> str:
    return f"""
audit_db: ":memory:"
lines:
  - name: dp
    port: {dp_url}
    protocol: profibus
    baudrate: 19200
    slot_time: 50ms
    alarms: off
    counters: off
    settings: off
    drives:
{chr(10).join(slaves)}
  - name: fc
    port: {fc_url}
    protocol: fc
    baudrate: 115200
    timeout: {fc_timeout}
    alarms: off
    counters: off
    settings: off
    drives:
      - name: press
        address: 1
        catalog: danfoss-fc
        poll: [{{parameter: "16-13", every: 100ms}}]
"""


@dataclass
class Lines:
    dp: DpSimulator
    wire: FrameLog
    dp_end: TcpEnd
    fc_end: TcpEnd
    runtime: Runtime
    reloader: Reloader
    text: list[str]  # the configuration file's text, as a reload reads it

    def metrics(self) -> str:
        return generate_latest(self.runtime.registry).decode()

    def value(self, drive: str, parameter: str) -> bool:
        head = (
            f'pkwbus_parameter_value{{drive="{drive}",index="0",line="dp",parameter="{parameter}"}}'
        )
        return head in self.metrics()


@asynccontextmanager
async def lines(addresses: tuple[int, ...]) -> AsyncIterator[Lines]:
    async with AsyncExitStack() as stack:
        dp = DpSimulator(
            (8, 9, 10), dialect="danfoss-pcv", timing=SimTiming(response_delay=0.001), seed=5
        )
        wire = log_frames(dp)
        dp_end = await dp.serve_tcp("127.0.0.1", 0)
        stack.push_async_callback(dp_end.close)
        fc = Simulator("fc", [1], timing=SimTiming(response_delay=0.002), catalog="danfoss-fc")
        fc_end = await fc.serve_tcp("127.0.0.1", 0)
        stack.push_async_callback(fc_end.close)
        slaves = [slave(a, ["16-13"]) for a in addresses]
        text = [config_text(dp_end.url, fc_end.url, slaves)]
        _, runtime, _, reloader = await reloadable(text, stack)
        found = Lines(dp, wire, dp_end, fc_end, runtime, reloader, text)
        await until(lambda: all(found.value(NAMES[a], "16-13") for a in addresses))
        yield found


async def reloadable(
    text: list[str], stack: AsyncExitStack, history: HistoryStore | None = None
) -> tuple[Config, Runtime, Parts, Reloader]:
    """The runtime of the configuration text ``text[0]``, started (stopped by ``stack``),
    and its reloader, which reads ``text[0]`` again; ``history``: the drives' logs and
    settings watched too."""

    def reread() -> Config:
        return parse_config(text[0], environ={})

    config = reread()
    runtime, parts = await assemble(config)
    memory = remember(config, runtime, history) if history is not None else None
    reloader = Reloader(config, reread, runtime, parts, memory)
    await runtime.start()
    stack.push_async_callback(runtime.stop)
    return config, runtime, parts, reloader


async def until(condition: Callable[[], bool], timeout: float = 30.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not condition():
        assert loop.time() < end, "condition not met in time"
        await asyncio.sleep(0.02)


async def test_a_slaves_polls_change_without_parametrising_it_again() -> None:
    async with lines((8, 9)) as found:
        before = sum(found.wire.set_prm().values())
        assert before == 2  # one each at the start
        found.text[0] = config_text(
            found.dp_end.url,
            found.fc_end.url,
            [slave(8, ["16-13"]), slave(9, ["16-13", "16-14"])],
        )
        outcome = await found.reloader.reload()
        assert outcome.loaded, outcome
        assert outcome.changes == ["line dp: drive pump: polls changed"]
        await until(lambda: found.value("pump", "16-14"))
        await asyncio.sleep(0.5)
        assert sum(found.wire.set_prm().values()) == before  # nothing parametrised again
        assert found.dp_end.connections == 1 and found.fc_end.connections == 1


async def test_a_slave_added_reopens_its_line_alone() -> None:
    async with lines((8, 9)) as found:
        found.text[0] = config_text(
            found.dp_end.url,
            found.fc_end.url,
            [slave(8, ["16-13"]), slave(9, ["16-13"]), slave(10, ["16-13"])],
        )
        outcome = await found.reloader.reload()
        assert outcome.loaded, outcome
        assert outcome.changes == ["line dp reopened"]
        await until(lambda: all(found.value(NAMES[a], "16-13") for a in (8, 9, 10)))
        # Every slave parametrised afresh on the reopened line (the watchdog follows the
        # slaves), the FC line beside it untouched.
        assert found.wire.set_prm()[(10, 2)] >= 1
        assert found.wire.set_prm()[(8, 2)] >= 2 and found.wire.set_prm()[(9, 2)] >= 2
        assert found.dp_end.connections == 2
        assert found.fc_end.connections == 1


async def test_a_line_of_another_bus_changed_leaves_the_dp_line_alone() -> None:
    async with lines((8, 9)) as found:
        before = sum(found.wire.set_prm().values())
        slaves = [slave(8, ["16-13"]), slave(9, ["16-13"])]
        found.text[0] = config_text(found.dp_end.url, found.fc_end.url, slaves, "300ms")
        outcome = await found.reloader.reload()
        assert outcome.changes == ["line fc reopened"], outcome
        await until(lambda: found.fc_end.connections == 2)
        await asyncio.sleep(0.5)
        assert sum(found.wire.set_prm().values()) == before
        assert found.dp_end.connections == 1


def gsd_text(user_prm: str) -> str:
    """A drive's GSD file in the shape vendors ship (the keys pkwbus reads of it)."""
    return (
        '#Profibus_DP\r\nGSD_Revision = 1\r\nVendor_Name = "Drives Ltd"\r\n'
        'Model_Name = "Test drive"\r\nIdent_Number = 0x0402\r\n19.2_supp = 1\r\n'
        "MaxTsdr_19.2 = 60\r\n"
        f"User_Prm_Data_Len = 1\r\nUser_Prm_Data = {user_prm}\r\n"
        'Module = "PPO 1" 0xF3,0xF1\r\n1\r\nEndModule\r\n'
    )


async def test_a_gsd_file_changed_under_the_same_name_reopens_its_line(tmp_path: Path) -> None:
    """Nothing in the configuration changed but the GSD file's content (its User_Prm data):
    the slaves are parametrised again with it, the line opened again alone."""
    gsd = tmp_path / "drive.gsd"
    gsd.write_text(gsd_text("0x00"))

    def with_gsd(address: int) -> str:
        return slave(address, ["16-13"]).replace("ident: 0x0402", f"gsd: {gsd}")

    async with lines((8, 9)) as found:
        found.text[0] = config_text(found.dp_end.url, found.fc_end.url, [with_gsd(8), with_gsd(9)])
        outcome = await found.reloader.reload()
        assert outcome.changes == ["line dp reopened"]  # from ident to a GSD file
        await until(lambda: all(found.value(NAMES[a], "16-13") for a in (8, 9)))
        before = sum(found.wire.set_prm().values())
        outcome = await found.reloader.reload()
        assert outcome.changes == []  # the same file: nothing changes
        gsd.write_text(gsd_text("0x01"))
        outcome = await found.reloader.reload()
        assert outcome.changes == ["line dp reopened"]
        await until(lambda: sum(found.wire.set_prm().values()) >= before + 2)
        sent = [f.data for f in found.wire.frames if f.dsap == Service.SET_PRM]
        assert sent[-1].endswith(b"\x01") and sent[0].endswith(b"\x00")
