"""What the DP tests share: the simulator on its ends, every request frame recorded."""

from __future__ import annotations

import asyncio
import contextlib
from collections import Counter
from collections.abc import AsyncIterator
from dataclasses import dataclass, field

from pkwbus.protocol import pzd
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp.services import Service
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.profibus.line import DpSimulator


@dataclass
class FrameLog:
    """Every request frame that reached the simulator, decoded."""

    frames: list[fdl.DataFrame] = field(default_factory=list)

    def set_prm(self) -> Counter[tuple[int, int]]:
        """Set_Prm requests by (slave, master)."""
        return Counter((f.da, f.sa) for f in self.frames if f.dsap == Service.SET_PRM)

    def data_exchanges(self) -> list[fdl.DataFrame]:
        return [f for f in self.frames if f.dsap is None and f.da != fdl.BROADCAST and f.data]

    def control_words(self, ppo_length: int) -> list[int]:
        """The control word of every PPO-write that went out (after the 4 PKW words)."""
        out = []
        for f in self.data_exchanges():
            assert len(f.data) == ppo_length, f
            out.append(int.from_bytes(f.data[8:10], "big"))
        return out

    def assert_never_took_control(self, ppo_length: int, *, some: bool = True) -> None:
        """Every PPO-write had a control word of 0 (bit 10 clear); ``some``: there were some."""
        words = self.control_words(ppo_length)
        assert words or not some, "no PPO-write went out"
        assert all(not pzd.takes_control(w) for w in words), [hex(w) for w in words]
        assert all(w == pzd.MONITORING_CTW for w in words)


def log_frames(sim: DpSimulator) -> FrameLog:
    """Wrap ``sim.answer`` so that every request frame is kept."""
    wire = FrameLog()
    answer = sim.answer

    def logged(frame: object, now: float | None = None) -> Answer | None:
        if isinstance(frame, fdl.DataFrame) and frame.control.is_request:
            wire.frames.append(frame)
        return answer(frame, now)

    sim.answer = logged  # type: ignore[method-assign]
    return wire


class FakeMaster:
    """A TCP end where another master passes tokens (SD4) every few milliseconds."""

    def __init__(self, every: float = 0.005) -> None:
        self.every = every
        self.url = ""
        self.received = bytearray()
        self._server: asyncio.Server | None = None
        self._tasks: list[asyncio.Task[None]] = []

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._client, "127.0.0.1", 0)
        host, port = self._server.sockets[0].getsockname()[:2]
        self.url = f"socket://{host}:{port}"

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        async def tokens() -> None:
            while True:
                writer.write(fdl.encode(fdl.Token(1, 1)))  # a lone master passes to itself
                await asyncio.sleep(self.every)

        task = asyncio.create_task(tokens())
        self._tasks.append(task)
        try:
            while data := await reader.read(4096):
                self.received += data
        except ConnectionError:
            pass
        finally:
            task.cancel()
            writer.close()

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 1)


@contextlib.asynccontextmanager
async def fake_master() -> AsyncIterator[FakeMaster]:
    fake = FakeMaster()
    await fake.start()
    try:
        yield fake
    finally:
        await fake.close()
