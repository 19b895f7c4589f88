"""The soak's simulated lines, in a process of their own: ``python -m tests.soak.sims``.

Each line of the plan (plan.py) gets its simulator on TCP or a pty, with faults
on every answer, its port lost at random (the simulator's own
:func:`pkwbus.sim.serving.ends.drop_at_random`), a drive that dies for a while at
random, and on PROFIBUS lines slaves that restart at random. A small HTTP
server answers the soak's questions (one JSON object each):

- ``POST /check`` with ``[[line, address, parameter, index, value], ...]``:
  which of the values the line never sent (``wrong``; record.py);
- ``GET /value?line=L&address=A&parameter=P``: what the drive holds now;
- ``GET /events``: lost ports, restarts and deaths so far, faults injected;
- ``POST /calm``: no more lost ports, deaths or restarts (faults on answers go
  on); every port and drive is back.

The first line on stdout is JSON: ``{"ports": {line: port}, "control": URL}``.
Runs until SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import signal
import sys
import time
from collections import Counter
from collections.abc import Awaitable, Callable
from functools import partial
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, urlsplit

from pkwbus.link import run as run_on_loop
from pkwbus.protocol.values.notation import parse_parameter
from pkwbus.sim import SimFaults, SimTiming, Simulator
from pkwbus.sim.profibus.line import DpFaults, DpSimulator, SlaveKind
from pkwbus.sim.serving.ends import PtyEnd, TcpEnd, drop_at_random

from .plan import BAUDRATE, LineSpec, soak_lines
from .record import SentValues

__all__ = ["Lines", "main"]

FAULTS = SimFaults(
    drop=0.01, corrupt=0.01, truncate=0.01, garbage=0.01, wrong_address=0.005, late=0.005,
    stale=0.01, late_seconds=0.4,
)  # fmt: skip
DP_FAULTS = DpFaults(drop=0.005, corrupt=0.005, garbage=0.005, stale=0.005, rs=0.001)
TIMING = SimTiming(response_delay=0.003, baudrate=BAUDRATE, wire_timing=True)
DEAD_FOR = 20.0  # seconds a drive stays dead


def simulator(line: LineSpec, seed: int) -> Simulator | DpSimulator:
    addresses = [d.address for d in line.drives]
    if line.protocol == "profibus":
        each = {d.address: SlaveKind(d.dialect or "profidrive", d.ident, d.catalog)
                for d in line.drives}  # fmt: skip
        return DpSimulator(addresses, timing=TIMING, faults=DP_FAULTS, seed=seed, each=each)
    catalog = line.drives[0].catalog
    return Simulator(line.protocol, addresses, timing=TIMING, faults=FAULTS, seed=seed,
                     catalog=catalog)  # fmt: skip


class Lines:
    """The simulated lines, their ends and what happened to them."""

    def __init__(self, plan: list[LineSpec], folder: Path, seed: int) -> None:
        self.plan = {line.name: line for line in plan}
        self.folder = folder
        self.rng = random.Random(seed)
        self.sims = {line.name: simulator(line, seed + i) for i, line in enumerate(plan)}
        self.sent = {name: SentValues(sim) for name, sim in self.sims.items()}
        self.ends: dict[str, TcpEnd | PtyEnd] = {}
        self.events: Counter[str] = Counter()
        self.troubled: list[asyncio.Task[None]] = []
        self.failed = asyncio.Event()  # a trouble failed (a port could not be made again)

    async def open(self) -> dict[str, str]:
        ports = {}
        for name, line in self.plan.items():
            sim = self.sims[name]
            if line.end == "pty":
                pty = await sim.serve_pty(str(self.folder / f"tty-{name}"))
                self.ends[name], ports[name] = pty, pty.path
            else:
                tcp = await sim.serve_tcp("127.0.0.1", 0)
                self.ends[name], ports[name] = tcp, tcp.url
        return ports

    async def close(self) -> None:
        for end in self.ends.values():
            await end.close()

    def trouble(self, drops: float, restarts: float, deaths: float) -> None:
        """Start what goes wrong at random, per line and hour: lost ports, restarting
        slaves (PROFIBUS), drives dead for a while."""
        self.troubled = [asyncio.ensure_future(t) for t in self._troubles(drops, restarts, deaths)]
        for task in self.troubled:
            task.add_done_callback(self._ended)

    def _ended(self, task: asyncio.Future[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            self.failed.set()

    async def calm(self) -> dict[str, Any]:
        """Stop the troubles: the lost ports and dead drives are back (as each one ends
        when cancelled)."""
        for task in self.troubled:
            task.cancel()
        ended = await asyncio.gather(*self.troubled, return_exceptions=True)
        failed = [repr(e) for e in ended if isinstance(e, Exception)]
        self.troubled = []
        return {"calm": True, "failed": failed}

    def _troubles(self, drops: float, restarts: float, deaths: float) -> list[Awaitable[None]]:
        out: list[Awaitable[None]] = []
        for name in self.plan:
            rng = random.Random(self.rng.random())
            said = self._counter(name, "port_lost")
            out.append(drop_at_random(self.ends[name], drops, 1.0, rng, said))
            out.append(self._at_random(deaths, rng, partial(self._die, name)))
            sim = self.sims[name]
            if isinstance(sim, DpSimulator):
                out.append(self._at_random(restarts, rng, partial(self._restart, name)))
        return out

    def _counter(self, line: str, what: str) -> Callable[[str], None]:
        def count(_: str) -> None:
            self._note(line, what)

        return count

    async def _at_random(
        self, per_hour: float, rng: random.Random, act: Callable[[], Awaitable[None]]
    ) -> None:
        if per_hour <= 0:
            return
        while True:
            await asyncio.sleep(rng.expovariate(per_hour / 3600))
            await act()

    async def _restart(self, line: str) -> None:
        sim = self.sims[line]
        assert isinstance(sim, DpSimulator)
        address = self.rng.choice(sorted(sim.slaves))
        sim.restart(address)
        self._note(line, "restart", address)

    async def _die(self, line: str) -> None:
        sim = self.sims[line]
        address = self.rng.choice(sorted(sim.drives))
        sim.kill(address)
        self._note(line, "drive_dead", address)
        try:
            await asyncio.sleep(DEAD_FOR)
        finally:
            sim.revive(address)
            print(time.strftime("%H:%M:%S"), line, "drive_revived", address, file=sys.stderr)

    def _note(self, line: str, what: str, address: int | None = None) -> None:
        """Count an event, and say when it happened on stderr (the soak's sims.log)."""
        self.events[f"{line} {what}"] += 1
        drive = "" if address is None else f" {address}"
        print(time.strftime("%H:%M:%S"), line, f"{what}{drive}", file=sys.stderr, flush=True)

    # ----------------------------------------------------------- answers

    def check(self, items: list[list[Any]]) -> dict[str, Any]:
        wrong = []
        for line, address, parameter, index, value in items:
            pnu = parse_parameter(str(parameter)).pnu
            if not self.sent[line].sent((int(address), pnu, int(index)), float(value)):
                wrong.append([line, address, parameter, index, value])
        return {"checked": len(items), "wrong": wrong}

    def value(self, line: str, address: int, parameter: str) -> dict[str, Any]:
        drive = self.sims[line].drives[address]
        return {"value": drive.params.number(parse_parameter(parameter).pnu)}

    def stats(self) -> dict[str, Any]:
        injected: Counter[str] = Counter()
        for sim in self.sims.values():
            injected.update(sim.stats.as_dict()["injected"])
        return {"events": dict(self.events), "injected": dict(injected)}


async def _control(lines: Lines, reader: asyncio.StreamReader, writer: Any) -> None:
    """One HTTP/1.0 request: the method, the target, a JSON body by Content-Length."""
    try:
        head = (await reader.readuntil(b"\r\n\r\n")).decode("latin-1").split("\r\n")
        length = next(
            (int(h.split(":")[1]) for h in head if h.lower().startswith("content-length:")), 0
        )
        body = await reader.readexactly(length) if length else b""
        try:
            status, answer = "200 OK", await _answer(lines, head[0], body)
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            status, answer = "400 Bad Request", {"error": f"{type(exc).__name__}: {exc}"}
        data = json.dumps(answer).encode()
        writer.write(
            f"HTTP/1.0 {status}\r\nContent-Type: application/json\r\n"
            f"Content-Length: {len(data)}\r\n\r\n".encode()
            + data
        )
        await writer.drain()
    except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, ConnectionError):
        pass
    finally:
        writer.close()


async def _answer(lines: Lines, request: str, body: bytes) -> dict[str, Any]:
    method, target = request.split()[:2]
    url = urlsplit(target)
    query = dict(parse_qsl(url.query))
    if method == "POST" and url.path == "/check":
        return lines.check(json.loads(body))
    if method == "GET" and url.path == "/value":
        return lines.value(query["line"], int(query["address"]), query["parameter"])
    if method == "GET" and url.path == "/events":
        return lines.stats()
    if method == "POST" and url.path == "/calm":
        return await lines.calm()
    raise ValueError(f"no {method} {url.path}")


async def serve(args: argparse.Namespace) -> None:
    lines = Lines(soak_lines(args.lines), Path(args.folder), args.seed)
    ports = await lines.open()
    server = await asyncio.start_server(lambda r, w: _control(lines, r, w), "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    print(json.dumps({"ports": ports, "control": f"http://127.0.0.1:{port}"}), flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    lines.trouble(args.drops_per_hour, args.restarts_per_hour, args.deaths_per_hour)
    waiting = [asyncio.ensure_future(stop.wait()), asyncio.ensure_future(lines.failed.wait())]
    await asyncio.wait(waiting, return_when=asyncio.FIRST_COMPLETED)
    for task in waiting:
        task.cancel()
    calmed = await lines.calm()
    server.close()
    await lines.close()
    if calmed["failed"]:  # a port that could not be made again: say so, exit 1
        raise RuntimeError(f"the simulated lines failed: {calmed['failed']}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m tests.soak.sims", description=__doc__)
    parser.add_argument("--lines", type=int, default=8)
    parser.add_argument("--folder", required=True, help="where the ptys' links go")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--drops-per-hour", type=float, default=6.0)
    parser.add_argument("--restarts-per-hour", type=float, default=12.0)
    parser.add_argument("--deaths-per-hour", type=float, default=4.0)
    run_on_loop(serve(parser.parse_args(argv)))


if __name__ == "__main__":
    main()
