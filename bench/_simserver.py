"""The simulator in its own process, for the benchmarks: ``pkwbus simulate`` plus flapping.

Takes every option of ``pkwbus simulate`` (``--pty PATH`` or ``--listen``),
and ``--flap ADDRESSES --flap-period SECONDS``: those drives die and come
back every period. The event loop uses ``select()`` (microsecond timeouts)
instead of epoll (millisecond timeouts, rounded up), so the simulated drives
answer when the wire timing says, not up to a millisecond later: the
benchmarks measure the master, not the simulator's timer granularity.

    python -m bench._simserver --protocol fc --pty /tmp/x --drives 1-3 \
        --wire-timing --baudrate 115200 --response-delay 2ms
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import selectors
import signal
import sys

from pkwbus.sim.cli import Plan, configure, parse_addresses, plan


async def _serve(p: Plan, flap: list[int], period: float) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    sim = p.sim
    if p.pty is not None:
        end: object = await sim.serve_pty(p.pty)
    else:
        assert p.listen is not None
        end = await sim.serve_tcp(*p.listen)
    print("ready", flush=True)
    parent = os.getppid()
    dead = False
    while not stop.is_set():
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), period if flap else 0.5)
        if os.getppid() != parent:
            break
        if flap:
            dead = not dead
            for address in flap:
                (sim.kill if dead else sim.revive)(address)
    await end.close()  # type: ignore[attr-defined]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    configure(parser)
    parser.add_argument("--flap", default="", help="addresses that die and revive")
    parser.add_argument("--flap-period", type=float, default=2.0)
    args = parser.parse_args(argv)
    the_plan = plan(args)
    flap = parse_addresses(args.flap)
    loop = asyncio.SelectorEventLoop(selectors.SelectSelector())
    try:
        loop.run_until_complete(_serve(the_plan, flap, args.flap_period))
    finally:
        loop.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
