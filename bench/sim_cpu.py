"""The simulator's own CPU cost per telegram: it bounds how far our benchmarks can go.

In process: ``Simulator.handle`` on a mix of FC reads (live and stored
parameters) and a write, timed with ``time.process_time``. Over TCP: a
client in another process sends requests one at a time, and this process
(the simulator's) measures its own CPU time per answered telegram.

    .venv/bin/python -m bench.sim_cpu [--telegrams 20000]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing
import socket
import time
from typing import Any

from bench._measure import markdown_table
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import FC, USS
from pkwbus.protocol.serial.telegram import encode_block, frame
from pkwbus.sim import SimTiming, Simulator


def requests(protocol: str) -> list[bytes]:
    d = FC if protocol == "fc" else USS
    pnus = (1613, 1614, 1610, 341) if protocol == "fc" else (21, 27, 32, 1082)
    out = [pkw.read(d, pnu) for pnu in pnus]
    out.append(pkw.write(d, pnus[3], 1000 if protocol == "fc" else 0x41200000, pkw.Width.DWORD))
    return [
        frame(1, encode_block(pkw.encode_request(r, d, d.default_ind_layout, 4), (0, 0)))
        for r in out
    ]


def in_process(protocol: str, n: int) -> float:
    sim = Simulator(protocol, [1, 2, 3], seed=1)
    batch = requests(protocol)
    start = time.process_time()
    for i in range(n):
        assert sim.handle(batch[i % len(batch)]) is not None
    return (time.process_time() - start) / n


def client(port: int, batch: list[bytes], n: int) -> None:
    with socket.create_connection(("127.0.0.1", port)) as sock:
        for i in range(n):
            request = batch[i % len(batch)]
            sock.sendall(request)
            got = 0
            while got < 16:
                got += len(sock.recv(256))


async def over_tcp(protocol: str, n: int) -> float:
    sim = Simulator(protocol, [1, 2, 3], timing=SimTiming(response_delay=0.0), seed=1)
    end = await sim.serve_tcp("127.0.0.1", 0)
    proc = multiprocessing.Process(target=client, args=(end.port, requests(protocol), n))
    start = time.process_time()
    proc.start()
    while proc.is_alive():
        await asyncio.sleep(0.05)
    used = time.process_time() - start
    await end.close()
    answered = sim.stats.as_dict()["responses"]
    assert answered == n, answered
    return used / n


def run(telegrams: int = 20_000) -> dict[str, Any]:
    """CPU per telegram of ``Simulator.handle`` (``telegrams`` of them) and over TCP (a
    quarter as many), FC and USS; with their table (for run_all)."""
    rows = []
    for protocol in ("fc", "uss"):
        for how, per in (
            ("handle()", in_process(protocol, telegrams)),
            ("over TCP", asyncio.run(over_tcp(protocol, telegrams // 4))),
        ):
            rows.append({"protocol": protocol.upper(), "how": how, "cpu_us": per * 1e6,
                         "rate": 1 / per})  # fmt: skip
    table = markdown_table(
        rows,
        {"protocol": "protocol", "how": "path", "cpu_us": "CPU µs per telegram",
         "rate": "telegrams/s of one core"},
        digits=1,
    )  # fmt: skip
    return {"rows": rows, "table": table, "telegrams": telegrams}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--telegrams", type=int, default=20_000)
    args = parser.parse_args()
    for row in run(args.telegrams)["rows"]:
        print(
            f"{row['protocol'].lower()} {row['how']}:  {row['cpu_us']:7.1f} us CPU per telegram "
            f"({row['rate']:8.0f}/s)"
        )


if __name__ == "__main__":
    main()
