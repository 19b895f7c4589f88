"""The built-in simulated drives of a ``sim://`` port: started with the line, on a pty.

Each FC or USS drive starts with a past: :data:`PAST_TRIPS` trips already in its own
logs, acknowledged hours ago by its runtime, so that the watch of the drives' logs shows
entries from the first minute (``make run``).
"""

from __future__ import annotations

import tempfile
from collections.abc import Awaitable, Callable
from pathlib import Path

from pkwbus.protocol.pkw.length import AUTO
from pkwbus.service import config as cfg
from pkwbus.sim import ModelConfig, SimTiming, Simulator
from pkwbus.sim.profibus.line import DpSimulator, SlaveKind

__all__ = ["DEFAULT_SIM_DELAY", "PAST_TRIPS", "start_dp_sim", "start_sim"]

DEFAULT_SIM_DELAY = 0.003
PAST_TRIPS = 2


async def start_sim(
    line: cfg.FcLine | cfg.UssLine, sim: cfg.SimPort
) -> tuple[str, Callable[[], Awaitable[None]]]:
    """Simulated drives of the line's shape, with a past in their own logs."""
    catalogs = {d.catalog for d in line.drives if d.catalog}
    first = line.drives[0]  # the config checked that the drives share one shape
    uss = first if isinstance(first, cfg.UssDrive) else None  # FC: one telegram shape
    simulator = Simulator(
        line.protocol,
        sim.drives,
        dialect=first.pkw_dialect.name,
        ind_layout=first.layout,
        # A drive learned by its answers is simulated as Siemens drives leave the factory.
        pkw_words=None if uss is None or uss.pkw_words == AUTO else uss.pkw_words,
        pzd_words=2 if uss is None else uss.pzd_words,
        timing=SimTiming(
            response_delay=sim.response_delay
            if sim.response_delay is not None
            else DEFAULT_SIM_DELAY
        ),
        catalog=next(iter(catalogs)) if len(catalogs) == 1 else None,
        refuse_descriptions=sim.refuse_descriptions,
        keypad_every=sim.keypad_every,
        model=ModelConfig(past_trips=PAST_TRIPS),
    )
    return await _serve_on_pty(simulator, line.name)


async def start_dp_sim(
    line: cfg.ProfibusLine, sim: cfg.SimPort
) -> tuple[str, Callable[[], Awaitable[None]]]:
    """Simulated slaves, each of its drive's dialect, ident and catalog (one PPO per line)."""
    each: dict[int, SlaveKind] = {}
    for drive in line.drives:
        found, _ = drive.dp.settings()
        each[drive.address] = SlaveKind(
            drive.pkw_dialect.name,
            found.ident if found is not None else None,
            drive.catalog or "default",
        )
    simulator = DpSimulator(
        sim.drives,
        ppo_number=line.drives[0].ppo,  # the config checked that the slaves share one PPO
        timing=SimTiming(
            response_delay=sim.response_delay if sim.response_delay is not None else 0.0
        ),
        each=each,
        refuse_descriptions=sim.refuse_descriptions,
        keypad_every=sim.keypad_every,
        # DP-V1 slaves when parametrised so; each record's response ready at the second read.
        dpv1=True,
        not_ready=1,
    )
    return await _serve_on_pty(simulator, line.name)


async def _serve_on_pty(
    simulator: Simulator | DpSimulator, line: str
) -> tuple[str, Callable[[], Awaitable[None]]]:
    """The simulator on a pty of a temporary folder: its path, and what closes both."""
    folder = Path(tempfile.mkdtemp(prefix="pkwbus-sim-"))
    end = await simulator.serve_pty(str(folder / f"tty-{line}"))

    async def close() -> None:
        await end.close()
        folder.rmdir()

    return end.path, close
