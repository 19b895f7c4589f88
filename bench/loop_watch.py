"""The watch of callbacks that hold the event loop: what it costs per callback.

``pkwbus.link.eventloop.watch_callbacks`` times every callback the service's
loop runs (one clock read and a comparison at each ``popleft`` of the loop's
queue of ready callbacks, one more before each wait). This measures, on the
same machine and in the same run, the CPU time per callback of trivial
callbacks (each queues the next with ``call_soon``):

- ``asyncio``: asyncio's own ``SelectorEventLoop``, for reference;
- ``pkwbus, not watched``: pkwbus's loop (``link.new_event_loop``) as the
  commands run it;
- ``pkwbus, watched``: the same loop while ``watch_callbacks`` watches it,
  as the service runs it;
- ``asyncio debug mode``: the other way to be told of a slow callback
  (``slow_callback_duration``), for scale.

``--chains`` callbacks run in each turn of the loop (the service runs
several per turn: the lines, HTTP, timers); with ``--chains 1`` every
callback is a turn of its own and the figure includes the wait before it.
The kinds run interleaved, ``--repeat`` times; the table gives the fastest
run of each (the one least disturbed by the rest of the machine) and the
difference to pkwbus's loop not watched.

    .venv/bin/python -m bench.loop_watch [--n 200000] [--chains 100] [--repeat 5]
"""

from __future__ import annotations

import argparse
import asyncio
import time
from collections.abc import Callable

from bench._measure import markdown_table
from pkwbus import link
from pkwbus.link.eventloop import watch_callbacks

KINDS = ("asyncio", "pkwbus, not watched", "pkwbus, watched", "asyncio debug mode")


def _loop(kind: str) -> tuple[asyncio.AbstractEventLoop, Callable[[], None] | None]:
    if kind.startswith("asyncio"):
        loop = asyncio.SelectorEventLoop()
        if kind == "asyncio debug mode":
            loop.set_debug(True)
            loop.slow_callback_duration = 0.1
        return loop, None
    loop = link.new_event_loop()
    if kind == "pkwbus, watched":
        return loop, watch_callbacks(loop, 0.1, lambda handle, held: None)
    return loop, None


def per_callback(kind: str, n: int, chains: int) -> float:
    """CPU seconds per callback of ``n`` trivial callbacks, ``chains`` of them per turn."""
    loop, unwatch = _loop(kind)
    try:
        per = max(1, n // chains)
        left = [per] * chains
        done = loop.create_future()
        running = [chains]

        def step(i: int) -> None:
            left[i] -= 1
            if left[i]:
                loop.call_soon(step, i)
                return
            running[0] -= 1
            if not running[0]:
                done.set_result(None)

        start = time.process_time()
        for i in range(chains):
            loop.call_soon(step, i)
        loop.run_until_complete(done)
        spent = time.process_time() - start
        if unwatch is not None:
            unwatch()
        return spent / (per * chains)
    finally:
        loop.close()


def run(n: int = 200_000, chains: int = 100, repeat: int = 5) -> dict[str, float]:
    """The fastest of ``repeat`` interleaved runs of each kind, seconds per callback."""
    best = dict.fromkeys(KINDS, float("inf"))
    for _ in range(repeat):
        for kind in KINDS:
            best[kind] = min(best[kind], per_callback(kind, n, chains))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200_000, help="callbacks per run")
    parser.add_argument("--chains", type=int, default=100, help="callbacks per turn")
    parser.add_argument("--repeat", type=int, default=5, help="interleaved runs of each")
    args = parser.parse_args()
    best = run(args.n, args.chains, args.repeat)
    base = best["pkwbus, not watched"]
    rows = []
    for kind, spent in best.items():
        extra = f"{(spent - base) * 1e9:+.0f}"
        rows.append({"loop": kind, "ns per callback": f"{spent * 1e9:.0f}", "difference": extra})
    print(f"{args.n} callbacks, {args.chains} per turn, fastest of {args.repeat}:")
    print(markdown_table(rows, ["loop", "ns per callback", "difference"]))


if __name__ == "__main__":
    main()
