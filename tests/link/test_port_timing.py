"""The link's timing: start pause to the microsecond, quiet line after an answer, direct writes."""

from __future__ import annotations

import asyncio
import tempfile
from pathlib import Path

import serial

from pkwbus.link import Link, PortSettings, new_event_loop
from pkwbus.link import run as run_on_pkwbus_loop
from pkwbus.link.eventloop import has_fine_timers
from pkwbus.link.serialport import raw_fd as _raw_fd
from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.sim import SimTiming, Simulator


def _request() -> bytes:
    target = DriveTarget.create("fc", 1)
    return SerialCarrier(target).telegram(pkw.read(target.dialect, 1613))


async def test_an_answer_ends_the_wait_for_our_own_request_to_leave_the_wire() -> None:
    # At 1200 baud a 16-byte request takes 147 ms on a real line; the pty
    # delivers it at once and the drive answers at once. The answer proves the
    # request has left the wire: the next request waits the start pause
    # (32 ms) after the answer, not the request's wire time.
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), seed=1)
    got = asyncio.Event()
    with tempfile.TemporaryDirectory() as tmp:
        end = await sim.serve_pty(str(Path(tmp) / "tty"))
        link = Link(PortSettings(end.path, baudrate=1200), receiver=lambda data: got.set())
        await link.open()
        try:
            loop = asyncio.get_running_loop()
            await link.send(_request())
            await asyncio.wait_for(got.wait(), 1.0)
            t0 = loop.time()
            await link.send(_request())
            waited = loop.time() - t0
        finally:
            await link.close()
            await end.close()
    pause = PortSettings(end.path, baudrate=1200).start_pause
    request_on_the_wire = len(_request()) * 11 / 1200
    assert pause - 0.002 <= waited < request_on_the_wire


async def test_a_start_pause_below_a_millisecond_is_kept_to_the_microsecond() -> None:
    link = Link(PortSettings("/dev/null", baudrate=115200))
    loop = asyncio.get_running_loop()
    waited = []
    for _ in range(21):
        t0 = loop.time()
        await link._pause_for(loop, 0.0003)
        waited.append(loop.time() - t0)
    await link.close()
    assert min(waited) >= 0.0003
    # The event loop's own timers would take a whole millisecond or more, every time; one
    # pause of the 21 under a millisecond shows they are not used (a loaded machine may
    # wake us late now and then, but it cannot make a pause shorter).
    assert min(waited) < 0.00095


async def test_a_longer_pause_is_never_cut_short() -> None:
    link = Link(PortSettings("/dev/null", baudrate=9600))
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    await link._pause_for(loop, 0.0042)
    assert loop.time() - t0 >= 0.0042
    await link.close()


def test_only_raw_ports_are_written_to_directly() -> None:
    loop_port = serial.serial_for_url("loop://", timeout=0)
    try:
        assert _raw_fd(loop_port) == -1
    finally:
        loop_port.close()


def test_on_pkwbus_loop_a_short_pause_needs_no_helper_thread() -> None:
    """select() waits to the microsecond: the pause is a plain sleep, no thread hand-off."""

    async def pauses() -> tuple[list[float], bool]:
        link = Link(PortSettings("/dev/null", baudrate=115200))
        loop = asyncio.get_running_loop()
        waited = []
        for _ in range(21):
            t0 = loop.time()
            await link._pause_for(loop, 0.0003)
            waited.append(loop.time() - t0)
        threads = link._fine_timer is not None
        await link.close()
        return waited, threads

    waited, threads = run_on_pkwbus_loop(pauses())
    assert not threads
    assert min(waited) >= 0.0003
    assert min(waited) < 0.00095  # not the loop's millisecond timers (see above)
    loop = new_event_loop()
    try:
        assert has_fine_timers(loop)
    finally:
        loop.close()
