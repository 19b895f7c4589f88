"""Hot standby (#47): how long a line goes without a master when its master is killed, and
what a quiet group costs etcd.

Takeover: two `pkwbus run` instances (a, b) on one configuration, a real single-member
etcd (Debian's etcd-server) on loopback, one FC line reached over TCP through a follower
that logs which process sent each request and when. ``--kills`` times the master is
killed with SIGKILL; each time, the seconds from the kill to the other instance's first
request at the follower; the killed instance is started again and registered before the
next kill. Median and max, with the lease (``--lease``, 4 s) they are bounded by: a standby
can take the line only once etcd let the killed master's lease expire.

etcd load: for each number of lines in ``--lines`` (one follower each), the same two
instances mastering them, nothing moving for ``--quiet`` seconds; the gRPC requests etcd
served meanwhile, from its own /metrics (``grpc_server_handled_total``: finished calls;
``grpc_server_msg_received_total``: messages, each lease keep-alive on a stream one), per
second, and per second per line.

    .venv/bin/python -m bench.standby_takeover [--kills 20] [--lease 4] [--quiet 60]
        [--lines 1,4]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import statistics
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from tests.service.standby_process.etcd import Etcd, etcd_binary
from tests.service.standby_process.follower import Follower
from tests.service.standby_process.group import Group

from bench._measure import markdown_table
from pkwbus import link


@contextlib.asynccontextmanager
async def running_group(tmp: Path, lines: int, lease: float) -> AsyncIterator[Group]:
    etcd = Etcd(tmp / "etcd", 1)
    followers = [Follower() for _ in range(lines)]
    group: Group | None = None
    try:
        await etcd.start()
        for line in followers:
            await line.start()
        group = Group(tmp, followers, etcd, lease=lease)
        yield group
    finally:
        if group is not None:
            await group.stop()
        for line in followers:
            await line.close()
        etcd.stop()


async def takeovers(kills: int, lease: float) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="pkwbus-bench-standby-") as tmp:
        async with running_group(Path(tmp), 1, lease) as group:
            master, standby = await group.master_and_standby()
            times = []
            for i in range(kills):
                before = await group.registration(master.name)
                killed = time.monotonic()
                await master.kill()
                first = await group.transmitting(standby.name, since=killed, timeout=lease + 60)
                times.append(first - killed)
                print(f"  kill {i + 1}: {master.name} -> {standby.name} {times[-1]:.2f} s",
                      file=sys.stderr)  # fmt: skip
                await group.start(master.name)
                await group.registered(master.name, after=before)
                master, standby = standby, master
            overlaps = group.follower.overlaps()
    return {
        "kills": kills,
        "lease s": lease,
        "median s": statistics.median(times),
        "max s": max(times),
        "min s": min(times),
        "two at once": len(overlaps),
    }


def has_requests(line: Follower) -> Callable[[], bool]:
    return lambda: bool(line.requests)


async def quiet_load(lines: int, lease: float, quiet: float) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="pkwbus-bench-standby-") as tmp:
        async with running_group(Path(tmp), lines, lease) as group:
            await group.start("a")
            await group.start("b")
            for name in "ab":
                await group.registered(name)
            # Settled: every line mastered, and then two leases with no line changing hands.
            for line in group.followers:
                await group.until("all lines mastered", lease + 60, has_requests(line))
            await asyncio.sleep(2 * lease)
            moved = [len(f.connections) for f in group.followers]
            before = await group.etcd.served()
            started = time.monotonic()
            await asyncio.sleep(quiet)
            after = await group.etcd.served()
            took = time.monotonic() - started
            assert moved == [len(f.connections) for f in group.followers], "a line moved"
    calls = (after["grpc_server_handled_total"] - before["grpc_server_handled_total"]) / took
    messages = after["grpc_server_msg_received_total"] - before["grpc_server_msg_received_total"]
    messages /= took
    return {
        "lines": lines,
        "seconds": took,
        "calls/s": calls,
        "calls/s per line": calls / lines,
        "messages/s": messages,
        "messages/s per line": messages / lines,
    }


async def measure(args: argparse.Namespace) -> None:
    if etcd_binary() is None:
        sys.exit("bench/standby_takeover.py: etcd is not installed (Debian package etcd-server)")
    rows = [await takeovers(args.kills, args.lease)]
    print("Takeover after kill -9 of the master (the other's first request at the line):")
    print(markdown_table(rows, list(rows[0]), digits=2))
    loads = [await quiet_load(n, args.lease, args.quiet) for n in args.lines]
    print()
    print(f"etcd requests while nothing moves (2 instances, lease {args.lease:g} s):")
    print(markdown_table(loads, list(loads[0]), digits=2))
    if len(loads) > 1:
        low, high = loads[0], loads[-1]
        extra = (high["calls/s"] - low["calls/s"]) / (high["lines"] - low["lines"])
        print(f"\neach line more: {extra:.2f} calls/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--lease", type=float, default=4.0)
    parser.add_argument("--quiet", type=float, default=60.0, help="seconds of the quiet window")
    parser.add_argument(
        "--lines", type=lambda s: [int(n) for n in s.split(",")], default=[1, 4],
        help="numbers of lines for the quiet load, comma separated",
    )  # fmt: skip
    args = parser.parse_args()
    loop = link.new_event_loop()
    try:
        loop.run_until_complete(measure(args))
    finally:
        loop.close()


if __name__ == "__main__":
    main()
