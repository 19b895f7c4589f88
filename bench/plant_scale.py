"""Plant scale: 4 lines x 126 drives x 20 values, with the status page and Prometheus.

Four simulated lines (one simulator process each, pty, wire timing at 115200
baud, 2 ms response delay, 126 Danfoss FC drives), benchmark 6's twenty
parameters on every drive, each polled every 20 s: 10,080 values. The drives'
counters (the catalog's default polls) are off, so that the values are the
twenty of each drive; the rest is as ``pkwbus run`` has it (the watch of the
drives' logs, the settings' sweep, the descriptions). The service runs in this
process (runtime from a configuration, FastAPI on uvicorn); every HTTP client
runs in another process (this script with ``--client``) over loopback.

Once every polled value has landed and the start's backlog has drained (the
lines' busy share over 10 s under 0.9; ``--settle`` seconds from the start at
most), windows of ``--seconds`` (best a whole poll interval, 20 s),
quiet ones (no HTTP client) and loaded ones in turn, each loaded window between
two quiet ones:

1. **quiet**: telegrams/s per line, from the lines' own counts (what
   ``pkwbus_telegrams_total`` counts).
2. **loaded**: the same while one client fetches what the status page fetches
   (``PAGES``: ``--page full`` as the page does today, ``--page overview`` as it
   would with ``?view=overview&changed_since=`` and one drive's detail) and
   another scrapes ``GET /metrics`` every 5 s; loaded / quiet (the mean of the
   quiet windows on either side). Goal: at least 0.95.
3. **GET /api/v1/drives**, the full answer, after the windows (the polls going
   on, no other client): wall time of the client in another process (read as
   ``GET /metrics`` below), median of
   ``--repeat`` requests 2 s apart (the page's period; one before them, not
   counted), and ms per 1,000 values in the answer (each drive's ``values``).
   Goal: at most 1 ms per 1,000 values.
4. **event-loop lag** of the service's process in each window: a task here
   sleeps 10 ms in a loop and records how late it wakes (p50, p99, max). Goal:
   p99 at most 20 ms while loaded.
5. **GET /metrics** ms per 1,000 values (``pkwbus_parameter_value`` series),
   the loaded window's scrapes (the first one, before the window, not counted),
   median, from the request's send to the body's last byte at a client that reads
   as Prometheus does (a blocking socket straight into one buffer). Goal: at most 1.0.

If the service does not understand ``?view=overview``, ``?drive=`` or
``?changed_since=`` (no ``X-Changes-Token`` header), ``--page overview`` says so
and is skipped.

    .venv/bin/python -m bench.plant_scale [--page full --page overview] [--seconds 20]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import socket
import statistics
import sys
import tempfile
import time
from collections.abc import AsyncIterator, Iterator
from typing import Any
from urllib.parse import quote, urlsplit

from bench._common import (
    Service,
    machine,
    machine_note,
    quiet_logs,
    registry_sum,
    service_config,
)
from bench._measure import ROOT, BenchSetupError, markdown_table, module_command
from bench.scale import BAUD, PARAMETERS, fc_lines
from pkwbus import link

# What the status page fetches (src/pkwbus/service/http/static/status.js), as (path,
# every seconds). A round fetches the 2 s paths together (the page's Promise.all), then
# each slower one that is due, one after another; the next round starts 2 s after the
# last one ended (the page's setTimeout). Not here: a drive's settings, fetched only for
# drives whose settings were swept whole (none within a run of this benchmark: the first
# sweep takes an hour), and the audit log, fetched only once a write token was typed.
# "{token}": the X-Changes-Token of the last answer ("&changed_since=" left out before the
# first); "{drive}": the one drive the page shows in detail.
PAGE_FULL: tuple[tuple[str, float], ...] = (
    ("/api/v1/lines", 2.0),
    ("/api/v1/drives", 2.0),
    ("/readyz", 2.0),
    ("/api/v1/trends", 15.0),
    ("/api/v1/events?limit=20", 10.0),
)
PAGE_OVERVIEW: tuple[tuple[str, float], ...] = (
    ("/api/v1/drives?view=overview&changed_since={token}", 2.0),
    ("/api/v1/lines", 2.0),
    ("/api/v1/drives?drive={drive}", 2.0),
)
PAGES = {"full": PAGE_FULL, "overview": PAGE_OVERVIEW}
DETAIL_DRIVE = "l0d1"  # the drive the overview page shows in detail
SCRAPE_EVERY = 5.0  # Prometheus's scrape_interval in deploy/prometheus

LINES = 4
DRIVES = 126
EVERY = 20.0  # seconds between two polls of a value
PERIOD = 2.0  # the page's refresh
WARMUP = 3.0  # seconds the clients run before a loaded window (their first answers make caches)
PROBE_SLEEP = 0.010  # the lag probe's sleep
TOKEN_HEADER = "x-changes-token"
SLICE = 10.0  # seconds of the lines' busy share while waiting for the start's backlog to drain
SETTLED = 0.9  # a busy share under this: the backlog has drained (about 0.8 with the polls)

BODY_BUFFER = 1 << 25  # bytes a client reads before it stops reading (32 MiB)

GOAL_RATIO = 0.95
GOAL_DRIVES_MS = 1.0  # per 1,000 values
GOAL_LAG_P99_MS = 20.0
GOAL_METRICS_MS = 1.0  # per 1,000 values


# --- the clients (this script with --client, in another process) ------------------------


class _Http:
    """One kept-alive HTTP/1.1 connection, as a browser's or Prometheus's; the body read
    whole into one buffer, not parsed (the service's time, not a Python client's)."""

    def __init__(self, base: str) -> None:
        url = urlsplit(base)
        self.host, self.port, self.netloc = url.hostname or "127.0.0.1", url.port, url.netloc
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None
        self.reconnects = 0

    async def get(self, path: str) -> tuple[int, dict[str, str], bytes]:
        request = f"GET {path} HTTP/1.1\r\nHost: {self.netloc}\r\n\r\n".encode()
        head, tries = b"", 0
        while not head:
            if self.reader is None or self.writer is None:
                # A buffer that takes a whole answer (as a browser's or Prometheus's
                # does): with asyncio's 64 KiB default the client would stop reading
                # every 128 KiB, and the service wait on a full socket.
                self.reader, self.writer = await asyncio.open_connection(
                    self.host, self.port, limit=BODY_BUFFER
                )
            try:
                self.writer.write(request)
                await self.writer.drain()
                head = await self.reader.readuntil(b"\r\n\r\n")
            except (ConnectionError, asyncio.IncompleteReadError):
                # the service closed the kept-alive connection (its 5 s keep-alive): again,
                # once, on a new one
                self.close()
                tries += 1
                if tries > 1:
                    raise
                self.reconnects += 1
        reader = self.reader
        assert reader is not None
        lines = head.decode("latin-1").split("\r\n")
        status = int(lines[0].split()[1])
        headers = {}
        for line in lines[1:]:
            key, _, value = line.partition(":")
            if key:
                headers[key.strip().lower()] = value.strip()
        if "content-length" in headers:
            body = await reader.readexactly(int(headers["content-length"]))
        elif headers.get("transfer-encoding", "").lower() == "chunked":
            body = await self._chunked()
        else:
            raise ConnectionError(f"GET {path}: an answer without a length")
        if headers.get("connection", "").lower() == "close":
            self.close()
        return status, headers, body

    async def _chunked(self) -> bytes:
        assert self.reader is not None
        parts = []
        while True:
            size = int((await self.reader.readuntil(b"\r\n")).split(b";")[0], 16)
            parts.append(await self.reader.readexactly(size + 2))
            if not size:
                return b"".join(p[:-2] for p in parts)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
        self.reader = self.writer = None


class _Record:
    """The answers of a client: latencies by path, sizes, errors."""

    def __init__(self) -> None:
        self.latencies: dict[str, list[float]] = {}
        self.sizes: dict[str, int] = {}
        self.errors: list[str] = []

    async def get(
        self, http: _Http, path: str, key: str, counted: bool
    ) -> tuple[int, dict[str, str], bytes]:
        t0 = time.perf_counter()
        status, headers, body = await asyncio.wait_for(http.get(path), 60.0)
        elapsed = time.perf_counter() - t0
        if status != 200 and not (path == "/readyz" and status == 503):
            self.errors.append(f"GET {path}: {status} {body[:200].decode(errors='replace')}")
        if counted:
            self.latencies.setdefault(key, []).append(elapsed)
        self.sizes[key] = len(body)
        return status, headers, body

    def out(self, **extra: object) -> dict[str, object]:
        return {"latencies": self.latencies, "sizes": self.sizes, "errors": self.errors[:5],
                "error_count": len(self.errors), **extra}  # fmt: skip


async def _page(base: str, page: str, duration: float, warmup: float) -> dict[str, object]:
    """The page's fetches for ``duration`` seconds; those started after ``warmup`` timed."""
    together = [path for path, every in PAGES[page] if every <= PERIOD]
    slower = [(path, every) for path, every in PAGES[page] if every > PERIOD]
    https = [_Http(base) for _ in together]
    record = _Record()
    token = ""
    last: dict[str, float] = {}
    start = time.monotonic()

    def filled(path: str) -> str:
        if not token:
            path = path.replace("&changed_since={token}", "")
        return path.format(token=quote(token), drive=quote(DETAIL_DRIVE))

    async def fetch(http: _Http, path: str, counted: bool) -> None:
        nonlocal token
        _, headers, _ = await record.get(http, filled(path), path, counted)
        if "{token}" in path:
            token = headers.get(TOKEN_HEADER, "")

    rounds = 0
    while time.monotonic() - start < duration and rounds < duration / PERIOD + 2:
        counted = time.monotonic() - start >= warmup
        await asyncio.gather(*(fetch(h, p, counted) for h, p in zip(https, together, strict=True)))
        for path, every in slower:
            if time.monotonic() - last.get(path, -1e9) >= every:
                last[path] = time.monotonic()
                await fetch(https[0], path, counted)
        rounds += 1
        await asyncio.sleep(PERIOD)
    for h in https:
        h.close()
    return record.out(rounds=rounds, reconnects=sum(h.reconnects for h in https))


class _Reader:
    """A kept-alive connection read as Prometheus's scraper or a browser reads an answer:
    a blocking socket in a process of its own, the body received straight into one
    buffer (``recv_into``), no work per piece. The asyncio client above pays Python's
    ``data_received`` and a copy for each 256 KiB of a 5 MB body, a few ms that are the
    client's, not the service's (seen: curl took 8 ms for a scrape where it took 13)."""

    def __init__(self, base: str) -> None:
        url = urlsplit(base)
        self.address = (url.hostname or "127.0.0.1", url.port or 80)
        self.netloc = url.netloc
        self.sock: socket.socket | None = None
        self.buffer = bytearray(BODY_BUFFER)
        self.reconnects = 0

    def get(self, path: str) -> tuple[int, memoryview, float]:
        """The status, the body (a view of the buffer, valid until the next get) and the
        seconds from the request's send to the body's last byte."""
        request = f"GET {path} HTTP/1.1\r\nHost: {self.netloc}\r\n\r\n".encode()
        for tries in range(2):
            if self.sock is None:
                self.sock = socket.create_connection(self.address, timeout=60.0)
                self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            t0 = time.perf_counter()
            try:
                self.sock.sendall(request)
                head, got = self._head()
            except ConnectionError:
                # the service closed the kept-alive connection (its 5 s keep-alive): again,
                # once, on a new one, the time counted from there
                self.close()
                if tries:
                    raise
                self.reconnects += 1
                continue
            break
        lines = bytes(head).decode("latin-1").split("\r\n")
        status = int(lines[0].split()[1])
        length = next(
            (int(v) for k, _, v in (line.partition(":") for line in lines[1:])
             if k.strip().lower() == "content-length"), None,
        )  # fmt: skip
        if length is None:
            raise ConnectionError(f"GET {path}: an answer without a Content-Length")
        if len(got) > length:
            raise ConnectionError(f"GET {path}: more bytes than the answer's Content-Length")
        if length > len(self.buffer):
            self.buffer = bytearray(length)
        view = memoryview(self.buffer)[:length]
        view[: len(got)] = got
        filled = len(got)
        assert self.sock is not None
        while filled < length:
            n = self.sock.recv_into(view[filled:])
            if not n:
                raise ConnectionError(f"GET {path}: the connection closed within the body")
            filled += n
        return status, view, time.perf_counter() - t0

    def _head(self) -> tuple[bytes, bytes]:
        assert self.sock is not None
        data = b""
        while b"\r\n\r\n" not in data:
            piece = self.sock.recv(65536)
            if not piece:
                raise ConnectionError("closed before an answer")
            data += piece
        head, _, rest = data.partition(b"\r\n\r\n")
        return head, rest

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
        self.sock = None


def _scrape(base: str, duration: float) -> dict[str, object]:
    """GET /metrics every SCRAPE_EVERY seconds for ``duration``, as Prometheus reads it
    (:class:`_Reader`); the first not counted."""
    scraper = _Reader(base)
    latencies: list[float] = []
    errors: list[str] = []
    values = size = 0
    start = time.monotonic()
    n = 0
    while time.monotonic() - start <= duration and n < duration / SCRAPE_EVERY + 2:
        t0 = time.monotonic()
        status, body, elapsed = scraper.get("/metrics")
        if status != 200:
            errors.append(f"GET /metrics: {status} {bytes(body[:200]).decode(errors='replace')}")
        if n > 0:
            latencies.append(elapsed)
        values = bytes(body).count(b"\npkwbus_parameter_value{")
        size = len(body)
        n += 1
        if t0 + SCRAPE_EVERY - start > duration:
            break
        time.sleep(max(0.0, t0 + SCRAPE_EVERY - time.monotonic()))
    scraper.close()
    return {"latencies": {"/metrics": latencies}, "sizes": {"/metrics": size},
            "errors": errors[:5], "error_count": len(errors), "values": values,
            "reconnects": scraper.reconnects}  # fmt: skip


def _drives(base: str, n: int) -> dict[str, object]:
    """GET /api/v1/drives n + 1 times, PERIOD apart, read as a browser reads it
    (:class:`_Reader`); the first not counted; the values in the last answer."""
    reader = _Reader(base)
    latencies: list[float] = []
    errors: list[str] = []
    body = b"[]"
    for i in range(n + 1):
        if i:
            time.sleep(PERIOD)
        status, view, elapsed = reader.get("/api/v1/drives")
        body = bytes(view)
        if status != 200:
            errors.append(f"GET /api/v1/drives: {status} {body[:200].decode(errors='replace')}")
        if i:
            latencies.append(elapsed)
    reader.close()
    views = json.loads(body)
    return {"latencies": {"/api/v1/drives": latencies}, "sizes": {"/api/v1/drives": len(body)},
            "errors": errors[:5], "error_count": len(errors), "drives": len(views),
            "values": sum(len(d["values"]) for d in views)}  # fmt: skip


async def _probe(base: str) -> dict[str, object]:
    """Whether the service understands ?view=overview, ?drive= and ?changed_since=."""
    try:
        problems = await _problems(_Http(base))
    except (ValueError, KeyError, TypeError) as e:  # not the JSON the new API answers
        problems = [f"an answer that is not the new API's: {e!r}"]
    return {"supported": not problems, "problems": problems}


async def _problems(http: _Http) -> list[str]:
    problems = []
    status, headers, body = await http.get("/api/v1/drives?view=overview")
    rows = json.loads(body) if status == 200 else []
    token = headers.get(TOKEN_HEADER, "")
    if status != 200:
        problems.append(f"?view=overview answered {status}")
    elif not token:
        problems.append("no X-Changes-Token header (no ?changed_since=)")
    if rows and "values" in rows[0]:
        problems.append("?view=overview answered the full views")
    status, _, body = await http.get(f"/api/v1/drives?drive={quote(DETAIL_DRIVE)}")
    if status != 200 or len(json.loads(body)) != 1:
        problems.append(f"?drive={DETAIL_DRIVE} did not answer that drive alone ({status})")
    if token:
        status, _, body = await http.get(
            f"/api/v1/drives?view=overview&changed_since={quote(token)}"
        )
        if status != 200 or len(json.loads(body)) >= max(2, len(rows)):
            problems.append(f"?changed_since= answered {status} with every drive")
    http.close()
    return problems


def _client_main(spec: dict[str, Any]) -> int:
    role, base = spec["role"], spec["base"]
    if role == "page":
        job = _page(base, spec["page"], spec["duration"], spec["warmup"])
    elif role == "metrics":
        print(json.dumps(_scrape(base, spec["duration"])))
        return 0
    elif role == "drives":
        print(json.dumps(_drives(base, spec["n"])))
        return 0
    else:
        job = _probe(base)
    print(json.dumps(asyncio.run(job)))
    return 0


# --- the service's side (this process) --------------------------------------------------


async def _start_client(**spec: object) -> asyncio.subprocess.Process:
    return await asyncio.create_subprocess_exec(
        *module_command("plant_scale", "--client", json.dumps(spec)), cwd=ROOT,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip


async def _result(proc: asyncio.subprocess.Process, timeout: float) -> dict[str, Any]:
    try:
        out, err = await asyncio.wait_for(proc.communicate(), timeout)
    except TimeoutError:
        proc.kill()
        await proc.wait()
        raise BenchSetupError(f"an HTTP client did not end within {timeout:.0f} s") from None
    if proc.returncode:
        raise BenchSetupError(f"an HTTP client failed:\n{err.decode(errors='replace')}")
    result: dict[str, Any] = json.loads(out)
    return result


async def _client(timeout: float, **spec: object) -> dict[str, Any]:
    proc = await _start_client(**spec)
    try:
        return await _result(proc, timeout)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


class LagProbe:
    """A task that sleeps PROBE_SLEEP in a loop and, while recording, keeps how late it
    woke (the event loop's lag as a timer in the service sees it)."""

    def __init__(self) -> None:
        self.samples: list[float] = []
        self.recording = False
        self.task: asyncio.Task[None] | None = None

    async def _run(self) -> None:
        while True:
            t0 = time.perf_counter()
            await asyncio.sleep(PROBE_SLEEP)
            if self.recording:
                self.samples.append(time.perf_counter() - t0 - PROBE_SLEEP)

    def start(self) -> None:
        self.task = asyncio.create_task(self._run(), name="bench-lag-probe")

    async def stop(self) -> None:
        if self.task is not None:
            self.task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self.task


def _pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def _telegrams(runtime: Any) -> dict[str, float]:
    """Telegrams exchanged so far, by line: the lines' own counts (pkwbus_telegrams_total
    is fed by the same events), not a registry collect() that holds the loop."""
    totals = getattr(runtime.snapshot, "totals", None)
    if totals:
        return {line: float(t.telegrams) for line, t in totals.items()}
    registry = runtime.registry
    return {
        line: registry_sum(registry, "pkwbus_telegrams_total", line=line)
        for line in runtime.runners
    }


async def _window(runtime: Any, probe: LagProbe, seconds: float) -> dict[str, Any]:
    """Telegrams/s per line, the loop's lag and this process's CPU over ``seconds``."""
    n0, c0, t0 = _telegrams(runtime), time.process_time(), time.perf_counter()
    probe.samples, probe.recording = [], True
    await asyncio.sleep(seconds)
    probe.recording = False
    n1, c1, t1 = _telegrams(runtime), time.process_time(), time.perf_counter()
    per_line = [(n1[k] - n0.get(k, 0.0)) / (t1 - t0) for k in sorted(n1)]
    lags = probe.samples
    return {
        "telegrams_s": statistics.fmean(per_line) if per_line else float("nan"),
        "per_line": per_line,
        "cpu": (c1 - c0) / (t1 - t0),
        "lag_p50_ms": _pct(lags, 0.50) * 1e3,
        "lag_p99_ms": _pct(lags, 0.99) * 1e3,
        "lag_max_ms": max(lags, default=float("nan")) * 1e3,
        "lag_samples": len(lags),
    }


async def _loaded(
    base: str, runtime: Any, probe: LagProbe, page: str, seconds: float
) -> dict[str, Any]:
    """A window while the page's client and the scraper run (each from WARMUP before)."""
    duration = WARMUP + seconds
    procs = [
        await _start_client(role="page", base=base, page=page, duration=duration, warmup=WARMUP),
        await _start_client(role="metrics", base=base, duration=duration),
    ]
    try:
        await asyncio.sleep(WARMUP)
        window = await _window(runtime, probe, seconds)
        page_out, scrape = [await _result(p, duration + 120.0) for p in procs]
    finally:
        for p in procs:
            if p.returncode is None:
                p.kill()
                await p.wait()
    return {**window, "page": page_out, "scrape": scrape}


def _busy(runtime: Any) -> float:
    """The lines' busy seconds on the wire so far, all lines together."""
    totals = getattr(runtime.snapshot, "totals", None)
    if totals:
        return float(sum(t.busy for t in totals.values()))
    return registry_sum(runtime.registry, "pkwbus_line_busy_seconds_total")


async def _settle(runtime: Any, limit: float) -> dict[str, float]:
    """Wait for a value of every polled parameter, then until the start's backlog has
    drained (the descriptions, the drives' logs read whole once, the polls they delayed
    keep the lines busy all the time, about a minute and a half): the lines' busy share
    over SLICE seconds under SETTLED; ``limit`` seconds at most in all."""
    keys = [(e.name, p.parameter, p.index) for e in runtime.drives.values() for p in e.polls]
    t0 = time.perf_counter()
    while True:
        readings = runtime.snapshot.readings
        missing = sum(1 for k in keys if k not in readings)
        if not missing:
            break
        if time.perf_counter() - t0 > limit:
            raise BenchSetupError(f"{missing} of {len(keys)} polled values not read in {limit} s")
        await asyncio.sleep(0.5)
    landed = time.perf_counter() - t0
    lines = max(1, len(_telegrams(runtime)))
    busy = 1.0
    while time.perf_counter() - t0 < limit:
        b0, w0 = _busy(runtime), time.perf_counter()
        await asyncio.sleep(SLICE)
        busy = (_busy(runtime) - b0) / (time.perf_counter() - w0) / lines
        if busy < SETTLED:
            break
    return {
        "polled": float(len(keys)),
        "landed_s": landed,
        "settled_s": time.perf_counter() - t0,
        "busy": busy,
    }


def plant_config(ports: list[str], drives: int, audit_db: str) -> str:
    """The plant's configuration: ``drives`` FC drives on each port, PARAMETERS polled every
    EVERY seconds, the twenty values of each drive only (not the catalog's counters)."""
    text = service_config(
        ports, drives=drives, pnus=PARAMETERS, every=f"{EVERY:g}s", baudrate=BAUD,
        audit_db=audit_db,
    )  # fmt: skip
    return text.replace("    protocol: fc\n", "    protocol: fc\n    counters: off\n")


@contextlib.asynccontextmanager
async def plant_service(
    ports: list[str], drives: int, extra: str = ""
) -> AsyncIterator[tuple[Service, LagProbe]]:
    """The service in this process on the plant's configuration (and ``extra`` YAML), with
    a LagProbe running."""
    with tempfile.TemporaryDirectory() as tmp:
        text = plant_config(ports, drives, f"{tmp}/audit.sqlite") + extra
        async with Service(text, nodelay=True) as service:
            probe = LagProbe()
            probe.start()
            try:
                yield service, probe
            finally:
                await probe.stop()


@contextlib.contextmanager
def plant_lines(lines: int, drives: int) -> Iterator[list[str]]:
    """The plant's simulated lines (a seed each), pkwbus's log at ERROR; their ptys."""
    with quiet_logs(), fc_lines(lines, drives, own_seeds=True) as ports:
        yield ports


async def _measure(
    ports: list[str], drives: int, seconds: float, pages: tuple[str, ...], repeat: int,
    settle: float,
) -> dict[str, Any]:  # fmt: skip
    async with plant_service(ports, drives) as (service, probe):
        runtime, base = service.runtime, service.base
        start = await _settle(runtime, settle)
        chosen = []
        skipped: dict[str, str] = {}
        for page in pages:
            if page == "overview":
                check = await _client(60.0, role="probe", base=base)
                if not check["supported"]:
                    skipped[page] = "; ".join(check["problems"])
                    print(
                        "plant_scale: the service does not understand the overview "
                        f"page's requests ({skipped[page]}): --page overview skipped",
                        file=sys.stderr, flush=True,
                    )  # fmt: skip
                    continue
            chosen.append(page)
        quiet = [await _window(runtime, probe, seconds)]
        loaded: dict[str, dict[str, Any]] = {}
        for page in chosen:
            loaded[page] = await _loaded(base, runtime, probe, page, seconds)
            quiet.append(await _window(runtime, probe, seconds))
        drives_get = await _client(60.0 + repeat * 30.0, role="drives", base=base, n=repeat)
    return {"start": start, "quiet": quiet, "loaded": loaded, "skipped": skipped,
            "drives_get": drives_get, "chosen": chosen}  # fmt: skip


def measure(
    lines: int = LINES,
    drives: int = DRIVES,
    seconds: float = 20.0,
    pages: tuple[str, ...] = ("full", "overview"),
    repeat: int = 7,
    settle: float = 240.0,
) -> dict[str, Any]:
    with plant_lines(lines, drives) as ports:
        return link.run(_measure(ports, drives, seconds, pages, repeat, settle))


# --- the figures ------------------------------------------------------------------------


def _met(ok: bool) -> str:
    return "yes" if ok else "no"


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def _rows(got: dict[str, Any]) -> tuple[list[dict[str, str]], list[dict[str, object]]]:
    """The figures against their goals; the page's requests while loaded."""
    quiet, start = got["quiet"], got["start"]
    rows: list[dict[str, str]] = [
        {"figure": "values polled (every 20 s): all landed, the start's backlog drained",
         "page": "-", "value": f"{start['polled']:,.0f}: after {start['landed_s']:.0f} s, "
                               f"{start['settled_s']:.0f} s (busy {start['busy']:.2f})",
         "goal": f"busy < {SETTLED}", "met": _met(start["busy"] < SETTLED)},
        {"figure": "telegrams/s per line, quiet windows", "page": "-",
         "value": " / ".join(f"{q['telegrams_s']:.1f}" for q in quiet), "goal": "", "met": ""},
        {"figure": "event-loop lag ms p50 / p99 / max, quiet", "page": "-",
         "value": " / ".join(f"{_median([q[k] for q in quiet]):.1f}"
                             for k in ("lag_p50_ms", "lag_p99_ms", "lag_max_ms")),
         "goal": "", "met": ""},
    ]  # fmt: skip
    requests: list[dict[str, object]] = []
    for i, page in enumerate(got["chosen"]):
        w = got["loaded"][page]
        around = statistics.fmean([quiet[i]["telegrams_s"], quiet[i + 1]["telegrams_s"]])
        ratio = w["telegrams_s"] / around if around else float("nan")
        scrape = w["scrape"]
        metric_s = scrape["latencies"].get("/metrics", [])
        per_k = _median(metric_s) * 1e3 / (scrape["values"] / 1000) if scrape["values"] else 0.0
        errors = w["page"]["error_count"] + scrape["error_count"]
        rows += [
            {"figure": "telegrams/s per line, loaded (quiet: the windows around)", "page": page,
             "value": f"{w['telegrams_s']:.1f} (quiet {around:.1f})", "goal": "", "met": ""},
            {"figure": "loaded / quiet", "page": page, "value": f"{ratio:.3f}",
             "goal": f"≥ {GOAL_RATIO}", "met": _met(ratio >= GOAL_RATIO)},
            {"figure": "event-loop lag ms p50 / p99 / max, loaded", "page": page,
             "value": f"{w['lag_p50_ms']:.1f} / {w['lag_p99_ms']:.1f} / {w['lag_max_ms']:.1f}",
             "goal": f"p99 ≤ {GOAL_LAG_P99_MS:g}", "met": _met(w["lag_p99_ms"] <= GOAL_LAG_P99_MS)},
            {"figure": f"GET /metrics ms per 1,000 values (median of {len(metric_s)}, "
                       f"every {SCRAPE_EVERY:g} s, loaded)", "page": page,
             "value": f"{per_k:.2f} ({_median(metric_s) * 1e3:.0f} ms, "
                      f"{scrape['values']:,} values)",
             "goal": f"≤ {GOAL_METRICS_MS}", "met": _met(per_k <= GOAL_METRICS_MS)},
            {"figure": "service CPU (cores), loaded / quiet", "page": page,
             "value": f"{w['cpu']:.2f} / {quiet[i]['cpu']:.2f}", "goal": "", "met": ""},
            {"figure": "HTTP errors while loaded", "page": page, "value": str(errors),
             "goal": "0", "met": _met(errors == 0)},
        ]  # fmt: skip
        for key, latencies in w["page"]["latencies"].items():
            requests.append({
                "page": page, "request": f"GET {key}", "n": len(latencies),
                "median_ms": _median(latencies) * 1e3, "max_ms": max(latencies) * 1e3,
                "kib": w["page"]["sizes"].get(key, 0) / 1024,
            })  # fmt: skip
    for page, why in got["skipped"].items():
        rows.append({"figure": "the overview page's requests", "page": page,
                     "value": f"skipped: the service does not understand them ({why})",
                     "goal": "", "met": ""})  # fmt: skip
    d = got["drives_get"]
    drive_s = d["latencies"].get("/api/v1/drives", [])
    per_k = _median(drive_s) * 1e3 / (d["values"] / 1000) if d["values"] else float("nan")
    rows.append({
        "figure": f"GET /api/v1/drives ms per 1,000 values (median of {len(drive_s)}, "
                  f"{PERIOD:g} s apart, no other client)", "page": "-",
        "value": f"{per_k:.2f} ({_median(drive_s) * 1e3:.0f} ms, {d['values']:,} values, "
                 f"{d['sizes'].get('/api/v1/drives', 0) / 2**20:.1f} MiB)",
        "goal": f"≤ {GOAL_DRIVES_MS}", "met": _met(per_k <= GOAL_DRIVES_MS),
    })  # fmt: skip
    return rows, requests


def run(
    seconds: float = 20.0,
    pages: tuple[str, ...] = ("full", "overview"),
    repeat: int = 7,
    settle: float = 240.0,
    lines: int = LINES,
    drives: int = DRIVES,
) -> dict[str, Any]:
    before = machine()
    got = measure(lines, drives, seconds, pages, repeat, settle)
    after = machine()
    rows, requests = _rows(got)
    columns = {"figure": "figure", "page": "page", "value": "measured", "goal": "goal",
               "met": "met"}  # fmt: skip
    table = markdown_table(rows, columns)
    if requests:
        table += "\n" + markdown_table(
            requests,
            {"page": "page", "request": "the page's requests while loaded", "n": "n",
             "median_ms": "median ms", "max_ms": "max ms", "kib": "KiB"},
            digits=1,
        )  # fmt: skip
    table += (
        f"\n{lines} lines × {drives} drives, {seconds:g} s windows. {machine_note(before, after)}\n"
    )
    return {"rows": rows, "requests": requests, "table": table, "measured": got}


def main() -> int:
    if len(sys.argv) > 2 and sys.argv[1] == "--client":  # one of the HTTP clients
        return _client_main(json.loads(sys.argv[2]))
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--page", choices=sorted(PAGES), action="append")
    parser.add_argument("--seconds", type=float, default=20.0, help="each window")
    parser.add_argument("--repeat", type=int, default=7, help="timed GET /api/v1/drives")
    parser.add_argument("--settle", type=float, default=240.0,
                        help="at most this many seconds to the first window")  # fmt: skip
    parser.add_argument("--lines", type=int, default=LINES)
    parser.add_argument("--drives", type=int, default=DRIVES)
    args = parser.parse_args()
    pages = tuple(args.page or ("full", "overview"))
    try:
        print(run(args.seconds, pages, args.repeat, args.settle, args.lines, args.drives)["table"])
    except BenchSetupError as e:
        print(f"plant_scale: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
