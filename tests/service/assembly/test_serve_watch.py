"""The running service (``root._serve``, in this process): its event loop is watched from
the start to the stop (``pkwbus_event_loop_lag_seconds``, a line for a callback that holds
it), and its stop waits for the drives' descriptions being written."""

from __future__ import annotations

import asyncio
import gc
import json
import logging
import os
import signal
import threading
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families

from pkwbus.service.assembly import root
from pkwbus.service.assembly.description_file import DescriptionFile
from pkwbus.service.assembly.serve import bind
from pkwbus.service.config import parse_config
from pkwbus.sim import SimTiming, Simulator
from tests.service.assembly.test_descriptions import config, fc_specs

DRIVES = """
      - name: d
        address: 1
        catalog: danfoss-fc
        settings: off
        events: off
        poll: [{parameter: "16-14", every: 100ms}]"""

SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)


class Running:
    """The service in this process: its HTTP client, its task, and its stop (SIGTERM, as
    ``pkwbus run`` is stopped; sent once, while the service's handler takes it)."""

    def __init__(self, client: httpx.AsyncClient, task: asyncio.Task[None]) -> None:
        self.client = client
        self.task = task
        self.stopped = False

    def stop(self) -> None:
        if not self.stopped:
            self.stopped = True
            os.kill(os.getpid(), signal.SIGTERM)


@asynccontextmanager
async def service(tmp_path: Path) -> AsyncIterator[Running]:
    """The service over one simulated FC drive, stopped when the block ends."""
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), specs=fc_specs(-3))
    server = await sim.serve_tcp("127.0.0.1", 0)
    text = f"audit_db: {tmp_path / 'audit.sqlite'}\n" + config(server.url, DRIVES)
    cfg = parse_config(text, environ={})
    audit = root.open_audit(cfg)
    history = root.open_history(cfg)
    sock = bind("127.0.0.1", 0)
    port = sock.getsockname()[1]
    handlers = {sig: signal.getsignal(sig) for sig in SIGNALS}
    task = asyncio.create_task(root._serve(cfg, sock, audit, history), name="service")
    try:
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=10) as client:
            # Answering: its signal handlers are set (before the lines and the HTTP server).
            await answering(client, task)
            running = Running(client, task)
            yield running
            running.stop()
            await asyncio.wait_for(asyncio.shield(task), 30)
    finally:
        if not task.done():
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        history.close()
        audit.close()
        await server.close()
        gc.unfreeze()  # the service settled its start-up heap


async def answering(client: httpx.AsyncClient, task: asyncio.Task[None]) -> None:
    deadline = time.monotonic() + 20
    while not task.done():
        try:
            if (await client.get("/healthz")).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        assert time.monotonic() < deadline, "the service did not answer within 20 s"
        await asyncio.sleep(0.05)
    task.result()  # it ended: why


def lag(text: str) -> dict[str, float]:
    found: dict[str, float] = {}
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            if sample.name == "pkwbus_event_loop_lag_seconds_bucket":
                found[sample.labels["le"]] = sample.value
            elif sample.name == "pkwbus_event_loop_lag_seconds_count":
                found["count"] = sample.value
    return found


async def hold(seconds: float) -> None:
    time.sleep(seconds)


async def test_the_service_exports_its_loops_lag_and_names_a_callback_that_holds_it(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)
    async with service(tmp_path) as running:
        client, task = running.client, running.task
        before = lag((await client.get("/metrics")).text)
        assert "+Inf" in before and "0.001" in before and "5.0" in before
        # The monitor wakes every 0.25 s: its wake falls in the first 0.25 s of the 0.4 s.
        await asyncio.create_task(hold(0.4), name="holder")

        async def late() -> bool:
            now = lag((await client.get("/metrics")).text)
            return now["count"] - now["0.1"] > before["count"] - before["0.1"]

        deadline = time.monotonic() + 20
        while not await late():
            assert time.monotonic() < deadline, "no wake over 0.1 s late after a 0.4 s hold"
            await asyncio.sleep(0.05)
    assert task.done() and task.exception() is None
    said = [r.getMessage() for r in caplog.records if r.name == "pkwbus.service.loop"]
    assert [m for m in said if m.startswith("task 'holder' (hold) held the event loop for")]
    # Stopped with the service: a hold now is no line.
    await asyncio.create_task(hold(0.15), name="after")
    await asyncio.sleep(0.01)
    assert not [r for r in caplog.records if "'after'" in r.getMessage()]


async def test_the_services_stop_waits_for_the_descriptions_being_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    made: list[Slow] = []

    class Slow(DescriptionFile):
        """Its first write waits until the test lets it go on."""

        gate = threading.Event()
        writing = threading.Event()

        def __init__(self, path: Path) -> None:
            super().__init__(path)
            made.append(self)

        def _write(self, text: str) -> None:
            self.writing.set()
            assert self.gate.wait(30)
            super()._write(text)

    monkeypatch.setattr(root, "DescriptionFile", Slow)
    path = tmp_path / "audit.sqlite.descriptions.json"
    async with service(tmp_path) as running:
        assert await asyncio.to_thread(Slow.writing.wait, 20)  # the drive described itself
        running.stop()
        done, _ = await asyncio.wait({running.task}, timeout=2.0)
        assert not done and not path.exists()  # it waits for the write (held at the gate)
        Slow.gate.set()
    (kept,) = made
    assert json.loads(path.read_text(encoding="utf-8")) == kept.book.to_json()
    assert kept.book.entries  # what the drive described
