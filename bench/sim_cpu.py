"""The simulator's own CPU cost per telegram: it bounds how far our benchmarks can go.

In process: ``Simulator.handle`` on a mix of FC reads (live and stored
parameters) and a write, timed with ``time.process_time``. Over TCP: a
client in another process sends requests one at a time, and this process
(the simulator's) measures its own CPU time per answered telegram.

    .venv/bin/python bench/sim_cpu.py [--telegrams 20000]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing
import socket
import time

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--telegrams", type=int, default=20_000)
    args = parser.parse_args()
    for protocol in ("fc", "uss"):
        per = in_process(protocol, args.telegrams)
        print(f"{protocol} handle():  {per * 1e6:7.1f} us CPU per telegram ({1 / per:8.0f}/s)")
        per = asyncio.run(over_tcp(protocol, args.telegrams // 4))
        print(f"{protocol} over TCP:  {per * 1e6:7.1f} us CPU per telegram ({1 / per:8.0f}/s)")


if __name__ == "__main__":
    main()
