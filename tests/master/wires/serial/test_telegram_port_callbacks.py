"""An exchange as a state machine in the line's callbacks: start pause, stray input, results."""

from __future__ import annotations

import asyncio

from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.planning.answers import ExchangeResult, Reply
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from tests.master.conftest import make_sim, open_port, serve


def _telegram(target: DriveTarget) -> bytes:
    return SerialCarrier(target).telegram(pkw.read(target.dialect, 1613))


async def test_an_exchange_runs_in_callbacks_and_hands_its_result_over() -> None:
    sim = make_sim("fc", [1])
    target = DriveTarget.create("fc", 1)
    async with serve(sim, "pty") as port, open_port(port, "fc") as (line, trace):
        got: asyncio.Future[ExchangeResult] = asyncio.get_running_loop().create_future()
        line.send(SerialCarrier(target).address, _telegram(target), got.set_result)
        assert line.busy
        result = await asyncio.wait_for(got, 2.0)
        assert isinstance(result, Reply) and result.adr == SerialCarrier(target).address
        assert not line.busy
        assert trace.tx == [_telegram(target)]


async def test_the_pause_counts_from_the_last_byte_and_preparation_uses_it_up() -> None:
    """Work done after the answer shortens the wait: past the pause, the request goes
    out at once, inside ``start``; right after the answer it waits for the pause."""
    sim = make_sim("fc", [1])
    target = DriveTarget.create("fc", 1)
    telegram = _telegram(target)
    async with serve(sim, "pty") as port, open_port(port, "fc", pause=0.02) as (line, trace):
        loop = asyncio.get_running_loop()
        pause = line.link.settings.start_pause
        assert isinstance(await line.exchange(SerialCarrier(target).address, telegram), Reply)
        answered = loop.time()
        # the pause's end: counted from the answer's last byte, which came before ``answered``
        # (by however long this task took to resume on a busy machine)
        due = answered + line.link.pause_left(answered)
        # at once after the answer: the request waits for the pause
        got: asyncio.Future[ExchangeResult] = loop.create_future()
        line.send(SerialCarrier(target).address, telegram, got.set_result)
        assert len(trace.tx) == 1
        sent_at: list[float] = []
        real_trace = line.trace
        assert real_trace is not None

        def stamp(direction: str, data: bytes) -> None:
            if direction == "tx":
                sent_at.append(loop.time())
            real_trace(direction, data)

        line.trace = stamp
        assert isinstance(await asyncio.wait_for(got, 2.0), Reply)
        assert len(trace.tx) == 2 and sent_at[0] >= due
        # preparation longer than the pause: no wait is left, the request goes out at once
        await asyncio.sleep(2 * pause)
        got = loop.create_future()
        line.send(SerialCarrier(target).address, telegram, got.set_result)
        assert len(trace.tx) == 3
        assert isinstance(await asyncio.wait_for(got, 2.0), Reply)


async def test_input_is_discarded_only_when_stray_bytes_arrived() -> None:
    sim = make_sim("fc", [1, 2])
    target = DriveTarget.create("fc", 1)
    telegram = _telegram(target)
    async with serve(sim, "pty") as port, open_port(port, "fc") as (line, _):
        flushes = 0
        real = line.link._discard_input

        def count() -> None:
            nonlocal flushes
            flushes += 1
            real()

        line.link._discard_input = count  # type: ignore[method-assign]
        for _ in range(5):
            assert isinstance(await line.exchange(SerialCarrier(target).address, telegram), Reply)
        clean = flushes
        line._on_data(b"\x00\x01")  # bytes nobody asked for, between exchanges
        assert isinstance(await line.exchange(SerialCarrier(target).address, telegram), Reply)
        assert isinstance(await line.exchange(SerialCarrier(target).address, telegram), Reply)
    assert clean <= 1  # at most the first request after opening
    assert flushes == clean + 1
