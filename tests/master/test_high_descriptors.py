"""A port whose descriptor is numbered 1024 or above (many HTTP connections open) is read."""

from __future__ import annotations

import gc
import os

from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import Answered
from pkwbus.protocol import pkw

from .conftest import make_sim, open_line, run_job, serve


async def test_a_device_port_above_select_s_limit_answers() -> None:
    """A device (here the simulator's pty) is read with read(2), whatever its number.

    pyserial's socket:// handler waits with select() on its own: the service keeps
    every descriptor below 1024 by its bound on HTTP connections."""
    end = "pty"
    sim = make_sim("fc", [7])
    sim.drives[7].set_value(341, 4321)
    target = DriveTarget.create("fc", 7)
    fillers: list[int] = []
    # A descriptor that garbage from an earlier test still holds is closed now: closed by
    # a collection between the filling and the opening, it would be the port's number.
    gc.collect()
    gc.disable()
    try:
        async with serve(sim, end) as port:
            while not fillers or fillers[-1] < 1100:
                fillers.append(os.open(os.devnull, os.O_RDONLY))
            async with open_line(port, "fc") as (line, _):
                assert line.link._fd >= 1024
                outcome = await run_job(line, target, pkw.read(target.dialect, 341))
                assert isinstance(outcome, Answered), outcome
                assert isinstance(outcome.response, pkw.ValueResponse)
                assert outcome.response.raw == 4321
    finally:
        gc.enable()
        for fd in fillers:
            os.close(fd)
