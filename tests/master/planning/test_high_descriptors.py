"""A port whose descriptor is numbered 1024 or above (many HTTP connections open) is read."""

from __future__ import annotations

import asyncio
import gc
import os

from pkwbus.link.serialport import closer
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from tests.master.conftest import make_sim, open_port, run_job, serve


async def test_a_device_port_above_select_s_limit_answers() -> None:
    """A device (here the simulator's pty) is read with read(2), whatever its number.

    pyserial's socket:// handler waits with select() on its own: the service keeps
    every descriptor below 1024 by its bound on HTTP connections."""
    end = "pty"
    sim = make_sim("fc", [7])
    sim.drives[7].set_value(341, 4321)
    target = DriveTarget.create("fc", 7)
    fillers: list[int] = []
    # Descriptors of earlier tests are freed now, not between the filling and the opening,
    # where the port would get the freed number: ports still being closed off the loop
    # (a socket:// close sleeps 0.3 s) and garbage still holding one.
    closed = await asyncio.get_running_loop().run_in_executor(None, closer.wait, 30.0)
    assert closed, "earlier ports still closing after 30 s"
    gc.collect()
    gc.disable()
    try:
        async with serve(sim, end) as port:
            while not fillers or fillers[-1] < 1100:
                fillers.append(os.open(os.devnull, os.O_RDONLY))
            async with open_port(port, "fc") as (line, _):
                assert line.link._fd >= 1024
                outcome = await run_job(line, target, pkw.read(target.dialect, 341))
                assert isinstance(outcome, Answered), outcome
                assert isinstance(outcome.response, pkw.ValueResponse)
                assert outcome.response.raw == 4321
    finally:
        gc.enable()
        for fd in fillers:
            os.close(fd)
