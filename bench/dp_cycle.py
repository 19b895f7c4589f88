"""PROFIBUS DP: Data_Exchange cycles per second with one slave, measured against the theory.

One simulated PPO 1 slave on a pty with wire timing (every request and answer
takes its 11 bits a character at the baud rate), pkwbus's DP master cycling
it. Printed per baud rate: the measured cycles/s, the theoretical best
(request + TSYN + min TSDR + answer + TID1, EN 50170 bus timing), and what a
USB adapter would cost (its latency timer, 1 ms in low-latency mode, 16 ms
otherwise, on each answer). The master is the service's: the line runner with
the DP wire, no job queued (the PKW slot stays at AK 0).

    python -m bench.dp_cycle [--seconds 3] [--baudrates 19200,93750]
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pkwbus.link import PortSettings, new_event_loop
from pkwbus.master.carriers import carrier_for
from pkwbus.master.events import Event, Exchanged
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.runner import LineRunner
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.profibus.port import FdlPort
from pkwbus.master.wires.profibus.wire import CycleWire, SlaveSpec
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import SlaveSetup, SlaveState
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.sim import SimTiming
from pkwbus.sim.profibus.line import DpSimulator

USB_LATENCY = {"low latency (1 ms)": 0.001, "default (16 ms)": 0.016}


def _frame_bytes(kind: ppo.PpoType) -> int:
    """A Data_Exchange request (and its answer) of this PPO on the wire, in bytes."""
    frame = fdl.DataFrame(8, 2, fdl.request_fc(fdl.Function.SRD_HIGH), data=bytes(kind.length))
    return len(fdl.encode(frame))


class _Count:
    """Counts the exchanges of the line's event stream."""

    def __init__(self) -> None:
        self.count = 0

    def on_events(self, events: Sequence[Event]) -> None:
        self.count += sum(isinstance(e, Exchanged) for e in events)


async def measure(baudrate: int, seconds: float) -> dict[str, Any]:
    # The simulated slave answers after min TSDR (11 bit times), as a quick real one would.
    delay = dp_timing.bits(dp_timing.MIN_TSDR_BITS, baudrate)
    timing = SimTiming(response_delay=delay, baudrate=baudrate, wire_timing=True)
    sim = DpSimulator([8], dialect="danfoss-pcv", timing=timing, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        end = await sim.serve_pty(str(Path(tmp) / "ttyDP"))
        try:
            line = FdlPort(
                PortSettings(end.path, baudrate=baudrate), 2, listen=0.01, clear_on_close=True
            )
            prm = dps.Parameters(sim.ident, dps.watchdog_factors(2.0))
            setup = SlaveSetup(8, 2, prm, sim.ppo.cfg, retries=2)
            target = DriveTarget.create("profibus", 8, dialect_name=sim.dialect.name)
            spec = DriveSpec("slave", carrier_for(target))
            wire = CycleWire([SlaveSpec(spec, setup, sim.ppo)])
            exchanges = _Count()
            runner = LineRunner("bench", line, wire, [spec], observers=[exchanges])
            task = asyncio.create_task(runner.run())
            loop = asyncio.get_running_loop()
            try:
                slave = wire.cycle.runs[8].slave
                while slave.state is not SlaveState.DATA_EXCHANGE:
                    await asyncio.sleep(0.01)
                runner.flush()
                start, first = loop.time(), exchanges.count
                await asyncio.sleep(seconds)
                runner.flush()
                count, elapsed = exchanges.count - first, loop.time() - start
            finally:
                runner.stop()
                await task
        finally:
            await end.close()
    size = _frame_bytes(sim.ppo)
    theory = dp_timing.exchange_time(size, size, baudrate)
    return {
        "baudrate": baudrate,
        "frame_bytes": size,
        "measured_per_s": count / elapsed,
        "theory_per_s": 1 / theory,
        "theory_ms": theory * 1000,
        "usb_per_s": {k: 1 / (theory + v) for k, v in USB_LATENCY.items()},
        "slot_time_ms": dp_timing.default_slot_time(baudrate) * 1000,
    }


def run(seconds: float = 3.0, baudrates: tuple[int, ...] = (19200, 93750)) -> list[dict[str, Any]]:
    loop = new_event_loop()
    try:
        return [loop.run_until_complete(measure(b, seconds)) for b in baudrates]
    finally:
        loop.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--baudrates", default="19200,93750")
    args = parser.parse_args()
    rates = tuple(int(b) for b in args.baudrates.split(","))
    for r in run(args.seconds, rates):
        usb = ", ".join(f"{k} {v:.1f}/s" for k, v in r["usb_per_s"].items())
        print(
            f"{r['baudrate']:>6} baud, PPO 1 ({r['frame_bytes']} bytes each way):"
            f" measured {r['measured_per_s']:.1f} cycles/s;"
            f" theory {r['theory_per_s']:.1f}/s ({r['theory_ms']:.2f} ms a cycle);"
            f" behind a USB adapter at most: {usb}; default slot time {r['slot_time_ms']:.0f} ms"
        )


if __name__ == "__main__":
    main()
