"""Shared plumbing of the pkwbus benchmarks: the simulator process, lines, statistics."""

from __future__ import annotations

import contextlib
import datetime
import gc
import logging
import os
import platform
import re
import selectors
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from bench._measure import ROOT, BenchSetupError, module_command, stop_process
from pkwbus.link import PortSettings
from pkwbus.master.carriers import carrier_for
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.protocol.buses import Bus

FC_TELEGRAM = 16  # bytes of an FC parameter telegram (PKW 4 words + PCD 2 words), each way
USS_TELEGRAM = 16  # USS with PKW 4 words + PZD 2 words


@contextlib.contextmanager
def sim_process(
    protocol: str = "fc",
    drives: str = "1",
    *,
    response_delay: float = 0.0,
    baudrate: int | None = None,
    wire_timing: bool = False,
    lag: int | str = 0,
    lag_mode: str = "none",
    dead: str = "",
    flap: str = "",
    flap_period: float = 2.0,
    catalog: str | None = None,
    timeout: float = 10.0,
    extra: Sequence[str] = (),
) -> Iterator[str]:
    """Run the simulator in another process on a new pty; yield the pty's path."""
    tmp = Path(tempfile.mkdtemp(prefix="pkwbus-bench-sim-"))
    path = tmp / "tty"
    argv = module_command(
        "_simserver",
        "--protocol",
        protocol,
        "--pty",
        str(path),
        "--drives",
        drives,
        "--response-delay",
        f"{response_delay:.6f}",
        "--lag",
        str(lag),
        "--lag-mode",
        lag_mode,
        "--seed",
        "1",
    )
    if baudrate:
        argv += ["--baudrate", str(baudrate)]
    if wire_timing:
        argv.append("--wire-timing")
    if dead:
        argv += ["--dead", dead]
    if flap:
        argv += ["--flap", flap, "--flap-period", str(flap_period)]
    if catalog:
        argv += ["--catalog", catalog]
    argv += extra  # any other option of pkwbus simulate
    with tempfile.TemporaryFile() as errors:
        proc = subprocess.Popen(
            argv,
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=errors,
            start_new_session=True,
        )
        try:
            assert proc.stdout is not None
            with selectors.DefaultSelector() as sel:
                sel.register(proc.stdout, selectors.EVENT_READ)
                ready = sel.select(timeout)
            if not ready or proc.stdout.readline().strip() != b"ready":
                stop_process(proc)
                errors.seek(0)
                detail = errors.read().decode(errors="replace")
                raise BenchSetupError(f"the simulator did not start:\n{detail}")
            yield str(path)
        finally:
            stop_process(proc)
            shutil.rmtree(tmp, ignore_errors=True)


def registry_sum(registry: object, name: str, **labels: str) -> float:
    """The sum of ``name``'s samples in a prometheus_client ``registry`` whose labels
    include ``labels``."""
    return sum(
        sample.value
        for family in registry.collect()  # type: ignore[attr-defined]
        for sample in family.samples
        if sample.name == name and all(sample.labels.get(k) == v for k, v in labels.items())
    )


def make_port(
    port: str, protocol: str = "fc", baudrate: int = 115200, **kw: object
) -> TelegramPort:
    return TelegramPort(PortSettings(port, baudrate=baudrate), Bus(protocol), **kw)  # type: ignore[arg-type]


def exchange_time(baudrate: int, request: int, response: int, delay: float) -> float:
    """Theoretical exchange time: both telegrams on the wire, start pause, response delay."""
    char = 11 / baudrate
    return request * char + 3.5 * char + delay + response * char


def best_median(values: Sequence[float], higher_is_better: bool = True) -> tuple[float, float]:
    best = max(values) if higher_is_better else min(values)
    return best, statistics.median(values)


def machine() -> dict[str, str]:
    model = "unknown"
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return {
        "cpu": model,
        "cores": str(os.cpu_count()),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "date": datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
        "load": load,
    }


@contextlib.contextmanager
def quiet_logs() -> Iterator[None]:
    """pkwbus's logger at ERROR for the block: the simulated drives' alarms and warnings
    come and go, and their log lines are not figures."""
    logger = logging.getLogger("pkwbus")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def machine_note(before: dict[str, str], after: dict[str, str]) -> str:
    """The machine and its load average at the start (``before``) and end (``after``)."""
    return (
        f"Machine: {before['cpu']}, {before['cores']} cores, Python {before['python']}; "
        f"load average {before['load']} at the start, {after['load']} at the end."
    )


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def now() -> float:
    return time.perf_counter()


class Counting:
    """An observer of the line's events that counts finished jobs per drive (the
    benchmarks' yardstick)."""

    def __init__(self) -> None:
        self.ok: dict[str, int] = {}
        self.failed: dict[str, int] = {}
        self.exchanges = 0

    def on_events(self, events: Sequence[object]) -> None:
        from pkwbus.master.events import Exchanged, JobDone
        from pkwbus.master.planning.outcomes import Answered

        for event in events:
            if isinstance(event, Exchanged):
                self.exchanges += 1
            elif isinstance(event, JobDone):
                answered = isinstance(event.result.outcome, Answered)
                book = self.ok if answered else self.failed
                book[event.drive] = book.get(event.drive, 0) + 1

    def total(self, drives: Sequence[str] | None = None) -> int:
        return sum(n for d, n in self.ok.items() if drives is None or d in drives)


def fc_drive(name: str, address: int, pnus: Sequence[int], every: float, protocol: str = "fc"):  # type: ignore[no-untyped-def]
    """A DriveSpec polling ``pnus`` every ``every`` seconds."""
    from pkwbus.master.planning.plan import DriveSpec, PollSpec
    from pkwbus.master.target import DriveTarget
    from pkwbus.protocol import pkw

    target = DriveTarget.create(protocol, address)
    polls = tuple(PollSpec(str(p), 0, pkw.read(target.dialect, p), every) for p in pnus)
    return DriveSpec(name, carrier_for(target), polls)


def service_config(
    ports: Sequence[str],
    *,
    drives: int,
    pnus: Sequence[str],
    every: str,
    baudrate: int,
    token_env: str = "PKWBUS_BENCH_TOKEN",
    audit_db: str = "",
    timeout: str = "100ms",
) -> str:
    """A ``pkwbus run`` configuration (YAML) with one line per port, FC drives 1..drives."""
    out = [
        "listen: 127.0.0.1:9725",
        f"api: {{write_token_env: {token_env}}}",
        f"audit_db: {audit_db or '/tmp/pkwbus-bench-audit.sqlite'}",
        "lines:",
    ]
    polls = ", ".join(f'{{parameter: "{p}", every: {every}}}' for p in pnus)
    for i, port in enumerate(ports):
        out += [
            f"  - name: line{i}",
            f"    port: {port}",
            "    protocol: fc",
            f"    baudrate: {baudrate}",
            f"    timeout: {timeout}",
            "    drives:",
        ]
        for a in range(1, drives + 1):
            out += [
                f"      - name: l{i}d{a}",
                f"        address: {a}",
                "        catalog: danfoss-fc",
                f"        poll: [{polls}]",
                '        writable: ["3-41", "3-42"]',
            ]
    return "\n".join(out) + "\n"


LISTENING = re.compile(rb"metrics on http://127\.0\.0\.1:(\d+)/metrics")
TELEGRAMS = re.compile(r"^pkwbus_telegrams_total\{[^}]*\} ([0-9.e+]+)$", re.M)


def telegrams_in(metrics: str) -> float:
    """The telegrams of all lines in a ``GET /metrics`` answer."""
    return sum(float(v) for v in TELEGRAMS.findall(metrics))


@dataclass(frozen=True)
class RunningService:
    """``pkwbus run`` in its own process: the process, its base URL, its log (stderr)."""

    process: subprocess.Popen[bytes]
    port: int
    log: Path

    @property
    def base(self) -> str:
        return f"http://127.0.0.1:{self.port}"


@contextlib.contextmanager
def pkwbus_run(
    config_text: str, folder: Path, name: str = "service", stop_timeout: float = 3.0
) -> Iterator[RunningService]:
    """``pkwbus run`` in its own process and session, on ``config_text`` (written to
    FOLDER/NAME.yaml) with ``--listen 127.0.0.1:0``, its stderr in FOLDER/NAME.log; yielded
    once its log says where it listens, stopped at the end (SIGTERM, then SIGKILL after
    ``stop_timeout`` seconds)."""
    config, log_path = folder / f"{name}.yaml", folder / f"{name}.log"
    config.write_text(config_text)
    with log_path.open("wb") as log:
        process = subprocess.Popen(
            [sys.executable, "-m", "pkwbus", "run", "--config", str(config),
             "--listen", "127.0.0.1:0"],
            stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
        )  # fmt: skip
        try:
            yield RunningService(process, _listening(log_path, process), log_path)
        finally:
            stop_process(process, stop_timeout)


def _listening(log: Path, process: subprocess.Popen[bytes]) -> int:
    """The port the service got for ``--listen 127.0.0.1:0``, from its log line."""
    deadline = time.monotonic() + 30
    while (found := LISTENING.search(log.read_bytes())) is None:
        if time.monotonic() > deadline or process.poll() is not None:
            raise BenchSetupError(f"pkwbus run did not start: see {log}")
        time.sleep(0.1)
    return int(found.group(1))


async def http_client(*args: str) -> dict[str, object]:
    """Run ``bench._http_client`` with ``args`` in another process; its JSON answer."""
    import asyncio
    import json

    proc = await asyncio.create_subprocess_exec(
        *module_command("_http_client", *args), cwd=ROOT,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await proc.communicate()
    if proc.returncode:
        raise BenchSetupError(f"the HTTP client failed:\n{err.decode(errors='replace')}")
    result: dict[str, object] = json.loads(out)
    return result


class Service:
    """The service in this process: runtime from a configuration, FastAPI app on uvicorn."""

    def __init__(self, config_text: str, *, nodelay: bool = False) -> None:
        self.config_text = config_text
        self.nodelay = nodelay
        self.base = ""

    async def __aenter__(self) -> Service:
        import asyncio

        import uvicorn

        from pkwbus.service.assembly.build import build_runtime
        from pkwbus.service.assembly.serve import bind, settle_heap
        from pkwbus.service.audit.log import AuditLog
        from pkwbus.service.config import parse_config
        from pkwbus.service.http.api import create_app

        config = parse_config(self.config_text)
        self.runtime = await build_runtime(config)
        self.audit = AuditLog(config.audit_db)
        app = create_app(self.runtime, audit=self.audit, write_token=config.write_token())
        self.sock = bind("127.0.0.1", 0) if not self.nodelay else _tcp_socket()
        self.base = f"http://127.0.0.1:{self.sock.getsockname()[1]}"
        self.server = uvicorn.Server(
            uvicorn.Config(app, log_config=None, access_log=False, lifespan="off")
        )
        settle_heap()  # as pkwbus run does
        await self.runtime.start()
        self.task = asyncio.create_task(self.server.serve(sockets=[self.sock]))
        while not self.server.started:
            await asyncio.sleep(0.01)
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.server.should_exit = True
        await self.task
        await self.runtime.stop()
        self.audit.close()
        self.sock.close()
        # The next benchmark in this process must not carry this service's objects.
        gc.unfreeze()
        gc.collect()


def _tcp_socket() -> socket.socket:
    """A listening socket made with IPPROTO_TCP, so that asyncio sets TCP_NODELAY on accepted
    connections (``pkwbus.service.assembly.serve.bind`` passes proto 0, and asyncio then
    leaves Nagle on)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    sock.listen(128)
    sock.setblocking(False)
    return sock
