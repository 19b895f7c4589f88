"""The floor: what any asyncio master pays per exchange, with and without the start pause.

pkwbus keeps the start pause of the FC and USS protocols (3.5 characters of
silence before every request, 0.33 ms at 115200 baud); pymodbus's async RTU
client does not wait before its requests, it writes the next one as soon as
the answer is in. On a zero-delay pty the answer comes back faster than the
pause, so a master that keeps it must be woken once more per exchange, after
the pause, to write. This benchmark measures what that wake-up costs, with
the smallest master that can be written on the same event loop, against the
same simulated drive, in the same run:

- ``bare, no pause``: a reader callback on the pty; when the answer is whole
  (length byte, BCC, address checked) the next request is written from the
  same callback. Nothing but the answer check: pymodbus's shape, minus
  everything a real master needs.
- ``bare, pause by timer``: the same, but the request waits for the rest of
  the 3.5-character pause, counted from the last byte received, by a loop
  timer (``call_later``), as ``pkwbus.master.wires.serial.port.Line`` does.
- ``bare, pause in place``: the rest of the pause spun away in the callback
  (no wake-up, but the pause is spent on the CPU: shown to bound the design).
- ``TelegramPort.start chain``: pkwbus's line, each exchange started from the
  previous one's result callback (the scheduler's way: no coroutine, no
  future per exchange).
- ``TelegramPort.exchange loop``: the same line, awaited one exchange at a time (the
  CLI's and the API's way).
- ``one wake-up, loop timer`` and ``one wake-up, select()``: no I/O at all,
  the process only sleeps one pause and wakes, by a loop timer on the same
  loop, and by a bare ``select()`` without a loop. An exchange that keeps the
  pause on a zero-delay pty sleeps twice (for the answer, then for the rest
  of the pause): twice the ``select()`` figure is what any master, in any
  language, pays on this machine before it does anything.

With pymodbus installed (``.[bench]``), its async RTU client in the same run
gives the ratios.

    .venv/bin/python -m bench.floor [--n 5000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import select
import statistics
import sys
import termios
import time
import tty
from collections.abc import Callable
from typing import Any

from bench._common import make_port, sim_process
from bench._measure import BenchSetupError, markdown_table, measure_cpu
from bench.cpu_per_exchange import raw_loop
from pkwbus import link
from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.planning.answers import Reply
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw

BAUDRATE = 115200
PAUSE = 3.5 * 11 / BAUDRATE  # FC protocol: 3.5 characters of 11 bits
WARMUP = 200


def request() -> bytes:
    target = DriveTarget.create("fc", 1)
    return SerialCarrier(target).telegram(pkw.read(target.dialect, 1613))


class Bare:
    """The smallest master: one FC request, answers checked by length, BCC and address."""

    def __init__(self, fd: int, telegram: bytes, total: int, pause: str) -> None:
        self.fd = fd
        self.telegram = telegram
        self.adr = telegram[2]
        self.total = total
        self.pause = pause
        self.count = 0
        self.bad = 0
        self.buf = bytearray()
        self.last_byte = 0.0
        self.loop = asyncio.get_running_loop()
        self.done: asyncio.Future[None] = self.loop.create_future()

    def send(self) -> None:
        self.buf.clear()
        os.write(self.fd, self.telegram)

    def on_readable(self) -> None:
        self.buf += os.read(self.fd, 256)
        buf = self.buf
        if len(buf) < 2 or len(buf) < buf[1] + 2:
            return
        self.last_byte = self.loop.time()
        bcc = 0
        for byte in buf[:-1]:
            bcc ^= byte
        if bcc != buf[-1] or buf[2] != self.adr or buf[0] != 0x02:
            self.bad += 1
        self.count += 1
        if self.count >= self.total:
            self.done.set_result(None)
            return
        if self.pause == "none":
            self.send()
        elif self.pause == "timer":
            left = PAUSE - (self.loop.time() - self.last_byte)
            if left > 0:
                self.loop.call_later(left, self.send)
            else:
                self.send()
        else:  # spin
            end = time.monotonic() + PAUSE - (self.loop.time() - self.last_byte)
            while time.monotonic() < end:
                pass
            self.send()


async def bare(port: str, n: int, pause: str, warmup: int = WARMUP) -> dict[str, float]:
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        tty.setraw(fd)
        termios.tcflush(fd, termios.TCIOFLUSH)
        loop = asyncio.get_running_loop()
        telegram = request()
        warm = Bare(fd, telegram, warmup, pause)
        loop.add_reader(fd, warm.on_readable)
        warm.send()
        await asyncio.wait_for(warm.done, 30)
        loop.remove_reader(fd)
        master = Bare(fd, telegram, n, pause)
        loop.add_reader(fd, master.on_readable)
        with measure_cpu(ops=n) as t:
            master.send()
            await asyncio.wait_for(master.done, 120)
        loop.remove_reader(fd)
    finally:
        os.close(fd)
    if warm.bad + master.bad:
        raise BenchSetupError(f"{warm.bad + master.bad} bad answers from the simulator")
    return {"cpu_us_per_op": t.cpu_us_per_op, "ops_per_s": t.ops_per_s}


async def line_chain(port: str, n: int, warmup: int = WARMUP) -> dict[str, float]:
    line = make_port(port, "fc", BAUDRATE, timeout=0.5)
    target = DriveTarget.create("fc", 1)
    telegram = request()

    async def chain(total: int) -> int:
        """``total`` exchanges, each started from the previous one's callback; the failures."""
        finished: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        count = bad = 0

        def done(result: object) -> None:
            nonlocal count, bad
            count += 1
            bad += not isinstance(result, Reply)
            if count >= total:
                finished.set_result(bad)
            else:
                line.send(SerialCarrier(target).address, telegram, done)

        line.send(SerialCarrier(target).address, telegram, done)
        return await asyncio.wait_for(finished, 120)

    await line.open()
    try:
        bad = await chain(warmup)
        with measure_cpu(ops=n) as t:
            bad += await chain(n)
    finally:
        await line.close()
    if bad:
        raise BenchSetupError(f"{bad} failed exchanges")
    return {"cpu_us_per_op": t.cpu_us_per_op, "ops_per_s": t.ops_per_s}


async def wake_timer(port: str, n: int) -> dict[str, float]:
    """``n`` wake-ups by a loop timer of one pause, nothing else (``port`` unused)."""
    loop = asyncio.get_running_loop()
    finished: asyncio.Future[None] = loop.create_future()
    count = 0

    def again() -> None:
        nonlocal count
        count += 1
        if count >= n:
            finished.set_result(None)
        else:
            loop.call_later(PAUSE, again)

    with measure_cpu(ops=n) as t:
        loop.call_later(PAUSE, again)
        await finished
    return {"cpu_us_per_op": t.cpu_us_per_op, "ops_per_s": t.ops_per_s}


async def wake_select(port: str, n: int) -> dict[str, float]:
    """``n`` sleeps of one pause in ``select()`` on nothing, no loop (``port`` unused)."""
    with measure_cpu(ops=n) as t:
        for _ in range(n):
            select.select([], [], [], PAUSE)
    return {"cpu_us_per_op": t.cpu_us_per_op, "ops_per_s": t.ops_per_s}


VARIANTS: dict[str, Callable[[str, int], Any]] = {
    "bare, no pause": lambda port, n: bare(port, n, "none"),
    "bare, pause by timer": lambda port, n: bare(port, n, "timer"),
    "bare, pause in place": lambda port, n: bare(port, n, "spin"),
    "TelegramPort.start chain": line_chain,
    "TelegramPort.exchange loop": raw_loop,  # benchmark 2's (a)
    "one wake-up, loop timer (no I/O)": wake_timer,
    "one wake-up, select() (no loop, no I/O)": wake_select,
}


def run(n: int = 5000, repeat: int = 3) -> dict[str, Any]:
    """Every variant ``repeat`` times, interleaved (one round = each variant once)."""
    try:
        from bench import pymodbus_baseline
    except ImportError:  # pragma: no cover - the bench extras are missing
        pymodbus_baseline = None
    runs: dict[str, list[dict[str, float]]] = {name: [] for name in VARIANTS}
    base: list[dict[str, Any]] = []
    for _ in range(repeat):
        for name, variant in VARIANTS.items():
            with sim_process("fc", "1") as port:
                runs[name].append(link.run(variant(port, n)))
        if pymodbus_baseline is not None:
            try:
                base.append(pymodbus_baseline.measure(n))
            except BenchSetupError as exc:
                print(f"pymodbus baseline skipped: {exc}", file=sys.stderr)
                pymodbus_baseline = None
    rows = []
    py = statistics.median(b["cpu_us_per_op"] for b in base) if base else None
    for name, results in runs.items():
        cpu = [r["cpu_us_per_op"] for r in results]
        median = statistics.median(cpu)
        row: dict[str, object] = {
            "variant": name,
            "CPU µs/exchange, min": min(cpu),
            "median": median,
            "exchanges/s, median": statistics.median(r["ops_per_s"] for r in results),
        }
        if py is not None:
            row["median / pymodbus"] = median / py
        rows.append(row)
    if py is not None:
        rows.append(
            {
                "variant": "pymodbus async RTU client (no start pause)",
                "CPU µs/exchange, min": min(b["cpu_us_per_op"] for b in base),
                "median": py,
                "exchanges/s, median": statistics.median(b["ops_per_s"] for b in base),
                "median / pymodbus": 1.0,
            }
        )
    columns = ["variant", "CPU µs/exchange, min", "median", "exchanges/s, median"]
    if py is not None:
        columns.append("median / pymodbus")
    return {
        "n": n,
        "repeat": repeat,
        "rows": rows,
        "table": markdown_table(rows, columns, digits=2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=5000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    try:
        result = run(args.n, args.repeat)
    except BenchSetupError as exc:
        print(f"floor: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    print(f"N={result['n']} exchanges a run, {result['repeat']} rounds, FC at {BAUDRATE} baud")
    print(result["table"])


if __name__ == "__main__":
    main()
