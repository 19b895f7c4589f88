"""Baseline: CPU cost per transaction of pymodbus's async RTU client.

The reference point for pkwbus's master: pymodbus's ``AsyncModbusSerialClient``
(RTU framer) does N sequential ``read_holding_registers(0, count=2)``
transactions against pymodbus's own async RTU server, over a pty pair made by
``socat`` (the stand-in for the RS-485 line). The server runs in a separate
process, so ``time.process_time()`` here counts the client's CPU only.

Run::

    .venv/bin/python -m bench.pymodbus_baseline --n 5000

or, from the benchmark runner, ``measure(5000)`` for a dict of the figures.
pymodbus is not a dependency of pkwbus; install it into the venv with
``.venv/bin/pip install pymodbus`` (it needs ``pyserial``, which pkwbus has).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import inspect
import logging
import os
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from bench._measure import (
    ROOT,
    BenchSetupError,
    Timing,
    measure_cpu,
    module_command,
    pty_pair,
    stop_process,
)

__all__ = ["measure"]

DEVICE_ID = 1
REGISTERS = [0x1234, 0x5678]  # what the server holds at addresses 0 and 1
BAUDRATE = 115200  # irrelevant on a pty, set for realism
WARMUP = 200
SERVER_START_TIMEOUT = 10.0
INSTALL_HINT = (
    "pymodbus is not installed; it is only needed for this baseline, not by pkwbus.\n"
    "Install it with: .venv/bin/pip install pymodbus pyserial-asyncio"
)


def _pymodbus_version() -> str:
    try:
        import pymodbus
    except ImportError as exc:
        raise BenchSetupError(INSTALL_HINT) from exc
    try:
        from pymodbus import FramerType  # noqa: F401  (3.7 and later)
    except ImportError as exc:
        raise BenchSetupError(
            f"pymodbus {pymodbus.__version__} is too old for this script (FramerType "
            "is missing); it needs pymodbus 3.7 or later: .venv/bin/pip install -U pymodbus"
        ) from exc
    return str(pymodbus.__version__)


# --------------------------------------------------------------------------
# server side (runs in a child process: ``pymodbus_baseline.py --serve PORT``)


def _server_context() -> Any:
    import pymodbus.datastore

    datastore: Any = pymodbus.datastore  # names differ between versions
    # block address 1 is protocol address 0: the data model is 1-based
    # (3.16 rejects block address 0 outright)
    block = datastore.ModbusSequentialDataBlock(1, [*REGISTERS, *([0] * 98)])
    # ModbusDeviceContext since 3.10, ModbusSlaveContext before
    device_cls = getattr(datastore, "ModbusDeviceContext", None) or datastore.ModbusSlaveContext
    device = device_cls(hr=block)
    return datastore.ModbusServerContext(device, single=True)


async def _serve(port: str) -> None:
    from pymodbus import FramerType
    from pymodbus.server import ModbusSerialServer

    server: Any = ModbusSerialServer(
        _server_context(), framer=FramerType.RTU, port=port, baudrate=BAUDRATE
    )
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    await server.serve_forever(background=True)
    print("ready", flush=True)
    parent = os.getppid()
    while not stop.is_set():  # also stop if our parent died without stopping us
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), 0.5)
        if os.getppid() != parent:
            break
    await server.shutdown()


@contextlib.contextmanager
def _server_process(port: str) -> Iterator[subprocess.Popen[bytes]]:
    """Start the pymodbus RTU server on ``port`` in a child process."""
    with tempfile.TemporaryFile() as errors:
        proc = subprocess.Popen(
            module_command("pymodbus_baseline", "--serve", port),
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=errors,
            start_new_session=True,  # Ctrl-C reaches us only; we stop it
        )
        try:
            _wait_ready(proc, errors)
            yield proc
        finally:
            stop_process(proc)


def _wait_ready(proc: subprocess.Popen[bytes], errors: IO[bytes]) -> None:
    assert proc.stdout is not None
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        ready = sel.select(SERVER_START_TIMEOUT)
    line = proc.stdout.readline() if ready else b""
    if line.strip() == b"ready":
        return
    stop_process(proc)
    errors.seek(0)
    detail = errors.read().decode(errors="replace").strip()
    why = "did not start" if not ready else f"exited with status {proc.returncode}"
    raise BenchSetupError(f"the pymodbus server {why}" + (f":\n{detail}" if detail else ""))


# --------------------------------------------------------------------------
# client side (this process, measured)


def _device_keyword(method: Any) -> str:
    """``device_id`` since pymodbus 3.10, ``slave`` before (``unit`` in 2.x)."""
    params = inspect.signature(method).parameters
    for name in ("device_id", "slave", "unit"):
        if name in params:
            return name
    raise BenchSetupError("cannot tell how this pymodbus version names the device address")


async def _run_client(port: str, n: int, warmup: int) -> tuple[Timing, int]:
    from pymodbus import FramerType
    from pymodbus.client import AsyncModbusSerialClient
    from pymodbus.exceptions import ModbusException

    client = AsyncModbusSerialClient(port=port, framer=FramerType.RTU, baudrate=BAUDRATE, timeout=1)
    kw: dict[str, Any] = {_device_keyword(client.read_holding_registers): DEVICE_ID}
    if not await client.connect():
        raise BenchSetupError(f"pymodbus client could not open {port}")
    errors = 0
    try:
        try:
            for _ in range(warmup):
                rr = await client.read_holding_registers(0, count=2, **kw)
                if rr.isError() or list(rr.registers) != REGISTERS:
                    raise BenchSetupError(f"unexpected answer in the warm-up: {rr}")
            with measure_cpu(ops=n) as timing:
                for _ in range(n):
                    rr = await client.read_holding_registers(0, count=2, **kw)
                    if rr.isError():
                        errors += 1
        except ModbusException as exc:
            raise BenchSetupError(f"transaction failed: {exc}") from exc
    finally:
        client.close()
    return timing, errors


def _cpu_seconds_of(pid: int) -> float:
    """CPU time (user + system) of another process, from /proc; NaN elsewhere."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return float("nan")


def measure(n: int, warmup: int = WARMUP) -> dict[str, Any]:
    """Run the baseline: ``n`` measured transactions after ``warmup`` unmeasured.

    Returns the client's figures (``cpu_us_per_op``, ``ops_per_s``, ``cpu_s``,
    ``wall_s``, ``utime_s``, ``stime_s``, ``cpu_load``, ...) plus ``name``,
    ``pymodbus``, ``errors`` and, for context only, the CPU the server process
    and socat spent per transaction during the measured run
    (``server_cpu_us_per_op``, ``socat_cpu_us_per_op``; coarse, clock ticks).
    Raises :class:`BenchSetupError` for expected failures (socat or pymodbus
    missing, server does not start, no answer).
    """
    if n <= 0:
        raise ValueError("n must be positive")
    version = _pymodbus_version()
    with (
        pty_pair() as (client_port, server_port, socat_pid),
        _server_process(server_port) as server,
    ):
        peers0 = (_cpu_seconds_of(server.pid), _cpu_seconds_of(socat_pid))
        timing, errors = asyncio.run(_run_client(client_port, n, warmup))
        peers1 = (_cpu_seconds_of(server.pid), _cpu_seconds_of(socat_pid))
    result: dict[str, Any] = {
        "name": f"pymodbus {version} async RTU client",
        "pymodbus": version,
        "warmup": warmup,
        "errors": errors,
        **timing.as_dict(),
        "server_cpu_us_per_op": (peers1[0] - peers0[0]) * 1e6 / n,
        "socat_cpu_us_per_op": (peers1[1] - peers0[1]) * 1e6 / n,
    }
    return result


# --------------------------------------------------------------------------
# command line


def _format(result: dict[str, Any]) -> str:
    line = (
        f"{result['name']}: {result['ops_per_s']:,.0f} transactions/s, "
        f"{result['cpu_us_per_op']:,.0f} us CPU per transaction (N={result['n']})"
    )
    details = (
        f"  client: cpu {result['cpu_s']:.3f} s (user {result['utime_s']:.3f}, "
        f"sys {result['stime_s']:.3f}), wall {result['wall_s']:.3f} s, "
        f"load {result['cpu_load']:.2f}, errors {result['errors']}\n"
        f"  peers (not counted): server ~{result['server_cpu_us_per_op']:,.0f} us, "
        f"socat ~{result['socat_cpu_us_per_op']:,.0f} us CPU per transaction"
    )
    return f"{line}\n{details}"


def _interrupt(signum: int, frame: object) -> None:
    # The answer to the transaction in flight will arrive after its request
    # was cancelled; pymodbus would log that as an error. It is expected now.
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="CPU cost per transaction of pymodbus's async RTU client "
        "against pymodbus's RTU server over a socat pty pair."
    )
    parser.add_argument("--n", type=int, default=5000, help="measured transactions (5000)")
    parser.add_argument(
        "--warmup", type=int, default=WARMUP, help=f"unmeasured transactions first ({WARMUP})"
    )
    parser.add_argument("--serve", metavar="PORT", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.n <= 0 or args.warmup < 0:
        parser.error("--n must be positive and --warmup not negative")

    try:
        if args.serve:
            _pymodbus_version()
            asyncio.run(_serve(args.serve))
            return 0
        # Ctrl-C and a plain `kill` stop quietly; the context managers clean up
        signal.signal(signal.SIGINT, _interrupt)
        signal.signal(signal.SIGTERM, _interrupt)
        started = time.monotonic()
        result = measure(args.n, args.warmup)
    except BenchSetupError as exc:
        print(f"{parser.prog}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{parser.prog}: interrupted", file=sys.stderr)
        return 130
    print(_format(result))
    if result["errors"]:
        print(f"{parser.prog}: {result['errors']} transactions failed", file=sys.stderr)
        return 1
    print(f"  ({time.monotonic() - started:.1f} s in all)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
