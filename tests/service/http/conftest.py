"""The HTTP API over the real service graph: simulator on TCP, build_runtime, FastAPI app.

``service()`` writes a configuration whose lines point at simulator TCP ends,
builds the runtime with :func:`build_runtime`, starts it and serves the app
to an ``httpx.AsyncClient`` through ``ASGITransport`` in the same loop. A
:class:`Recorder` sees every PKW request a simulated drive executes, so a
test can prove that a refused write sent nothing.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest

from pkwbus.master.planning.identity import identity_requests
from pkwbus.protocol.pkw import PkwRequest, PkwResponse
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.assembly.history import remember
from pkwbus.service.audit.log import AuditLog
from pkwbus.service.config import Config, parse_config
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.http.api import Api, build_api
from pkwbus.service.runtime import Runtime
from pkwbus.sim import ModelConfig, SimFaults, SimTiming, Simulator

TOKEN = "s3cret-Write-Token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
STEADY = ModelConfig(warning_rate=0.0, trip_rate=0.0)  # noise stays, nothing random happens
FC_DRIVES = ("fan1", "fan2", "fan3")


@dataclass
class Recorder:
    """Every PKW request each simulated drive executed, decoded, in order; the requests the
    service makes at its start to describe the drives (their identity, then AK 4) apart."""

    requests: list[tuple[int, PkwRequest]] = field(default_factory=list)
    descriptions: list[tuple[int, PkwRequest]] = field(default_factory=list)
    # called after a request is executed: (address, request, response) -> None
    after: list[Callable[[int, PkwRequest, PkwResponse], None]] = field(default_factory=list)

    def attach(self, sim: Simulator) -> None:
        identity = set(identity_requests(sim.dialect))
        for address, drive in sim.drives.items():
            params = drive.params
            original = params.execute

            def execute(
                req: PkwRequest,
                _address: int = address,
                _original: Callable[[PkwRequest], PkwResponse] = original,
            ) -> PkwResponse:
                described = req.command is Command.READ_DESCRIPTION or req in identity
                (self.descriptions if described else self.requests).append((_address, req))
                resp = _original(req)
                for hook in self.after:
                    hook(_address, req, resp)
                return resp

            params.execute = execute  # type: ignore[method-assign]

    def writes(self, address: int | None = None, pnu: int | None = None) -> list[PkwRequest]:
        return [
            r
            for a, r in self.requests
            if r.is_write and (address is None or a == address) and (pnu is None or r.pnu == pnu)
        ]

    def for_pnu(self, address: int, pnu: int) -> list[PkwRequest]:
        return [r for a, r in self.requests if a == address and r.pnu == pnu]


@dataclass
class Service:
    sims: dict[str, Simulator]
    audit_writer: Recorder
    config: Config
    runtime: Runtime
    audit: AuditLog | None
    audit_path: Path
    client: httpx.AsyncClient
    app: Any
    api: Api

    @property
    def sim(self) -> Simulator:
        return self.sims["fc"]

    async def put(
        self,
        drive: str,
        parameter: str,
        body: dict[str, Any],
        headers: dict[str, str] | None = None,
    ) -> httpx.Response:
        return await self.client.put(
            f"/api/v1/drives/{drive}/parameters/{parameter}",
            json=body,
            headers=AUTH if headers is None else headers,
        )


def line_yaml(
    name: str,
    url: str,
    protocol: str,
    drives: list[dict[str, Any]],
    *,
    timeout: float = 0.1,
    retries: int = 1,
    settings: str = "off",
    inter_char_timeout: float | None = None,
) -> str:
    lines = [
        f"  - name: {name}",
        f"    port: {url}",
        f"    protocol: {protocol}",
        "    baudrate: 115200",
        f"    timeout: {timeout}",
        f"    retries: {retries}",
        *([f"    inter_char_timeout: {inter_char_timeout}"] if inter_char_timeout else []),
        # The tests count the requests: no alarm words polled beyond what they poll.
        "    alarms: off",
        # Nor settings swept, unless a test sweeps them.
        f"    settings: {settings}",
        "    drives:",
    ]
    for d in drives:
        lines.append(f"      - name: {d['name']}")
        lines.append(f"        address: {d['address']}")
        lines.append(f"        catalog: {d['catalog']}")
        polls = d.get("poll", [])
        if polls:
            lines.append("        poll:")
            lines += [f'          - {{parameter: "{p}", every: {e}}}' for p, e in polls]
        writable = ", ".join(f'"{w}"' for w in d.get("writable", []))
        lines.append(f"        writable: [{writable}]")
        if "describe" in d:
            lines.append(f"        describe: {d['describe']}")
        if "parameters" in d:  # {key: a YAML flow mapping of its settings}
            lines.append("        parameters:")
            lines += [f'          "{k}": {v}' for k, v in d["parameters"].items()]
        if "counters" in d:
            lines.append(f"        counters: {d['counters']}")
    return "\n".join(lines)


# A write's old value is the latest the drive confirmed: tests of old values poll these.
POLLED_WRITABLES = [("16-13", "50ms"), ("3-41", "50ms"), ("1-20", "50ms")]


def fc_drives(
    polls: list[tuple[str, str]] | None = None, writable: list[str] | None = None
) -> list[dict[str, Any]]:
    polls = [("16-13", "50ms")] if polls is None else polls
    writable = ["3-41", "3-42", "1-20", "4-14"] if writable is None else writable
    return [
        {
            "name": name,
            "address": i + 1,
            "catalog": "danfoss-fc",
            "poll": polls,
            "writable": writable,
        }
        for i, name in enumerate(FC_DRIVES)
    ]


USS_DRIVES = [
    {
        "name": "pump1",
        "address": 1,
        "catalog": "siemens-g120",
        "poll": [("r0021", "100ms")],
        "writable": ["p1120", "p1121"],
    }
]


@asynccontextmanager
async def service(
    tmp_path: Path,
    *,
    token: str | None = TOKEN,
    fc: list[dict[str, Any]] | None = None,
    uss: list[dict[str, Any]] | None = None,
    timing: SimTiming | None = None,
    faults: SimFaults | None = None,
    line_timeout: float = 0.1,
    inter_char_timeout: float | None = None,
    retries: int = 1,
    audit: bool = True,
    read_token: str | None = None,
    settings: str = "off",
    keep: dict[str, Simulator] | None = None,
    ready: bool = True,
) -> AsyncIterator[Service]:
    """A running service: simulators, runtime, app and client; stopped on exit. ``ready``:
    entered once every drive described its parameters and has its first values (False:
    at once, for a drive that never answers)."""
    fc = fc_drives() if fc is None else fc
    timing = timing or SimTiming(response_delay=0.002)
    audit_writer = Recorder()
    async with AsyncExitStack() as stack:
        sims: dict[str, Simulator] = {}
        blocks = []
        for protocol, drives, catalog in (("fc", fc, "danfoss-fc"), ("uss", uss, "siemens-g120")):
            if not drives:
                continue
            kept = keep.get(protocol) if keep is not None else None
            sim = kept or Simulator(
                protocol,
                [d["address"] for d in drives],
                timing=timing,
                faults=faults,
                catalog=catalog,
                seed=11,
                model=STEADY,  # tests check "running" and the values: no random trips
            )
            if keep is not None:  # the same drives for the next service (a restart)
                keep[protocol] = sim
            audit_writer.attach(sim)
            end = await sim.serve_tcp("127.0.0.1", 0)
            stack.push_async_callback(end.close)
            sims[protocol] = sim
            blocks.append(
                line_yaml(
                    f"line_{protocol}",
                    end.url,
                    protocol,
                    drives,
                    timeout=line_timeout,
                    retries=retries,
                    settings=settings,
                    inter_char_timeout=inter_char_timeout,
                )
            )
        audit_path = tmp_path / "audit.sqlite"
        text = "\n".join(
            [
                "listen: 127.0.0.1:9725",
                f"audit_db: {audit_path}",
                "api:",
                "  write_token_env: TEST_PKWBUS_TOKEN",
                *(["  read_token_env: TEST_PKWBUS_READ_TOKEN"] if read_token else []),
                "lines:",
                *blocks,
            ]
        )
        env = {"TEST_PKWBUS_TOKEN": token} if token is not None else {}
        if read_token is not None:
            env["TEST_PKWBUS_READ_TOKEN"] = read_token
        config = parse_config(text, environ=env)
        runtime = await build_runtime(config)
        if settings != "off":  # swept and kept as by pkwbus run
            history = HistoryStore(tmp_path / "history.sqlite")
            stack.callback(history.close)
            remember(config, runtime, history)
        await runtime.start()
        stack.push_async_callback(runtime.stop)
        if ready:
            await wait_ready(runtime)
        log = AuditLog(config.audit_db) if audit else None
        if log is not None:
            stack.callback(log.close)
        tokens = {"write_token": config.write_token(env)}
        if read_token is not None:
            tokens["read_token"] = config.read_token(env)
        api = build_api(runtime, audit=log, **tokens)
        app = api.app
        client = httpx.AsyncClient(
            transport=httpx.ASGITransport(app=app), base_url="http://pkwbus.test", timeout=30.0
        )
        stack.push_async_callback(client.aclose)
        yield Service(sims, audit_writer, config, runtime, log, audit_path, client, app, api)


async def wait_ready(runtime: Runtime, timeout: float = 20.0) -> None:
    """Until every line's port is open, every drive has described its parameters (AK 4) and
    every polled parameter has a first value (generous: the machine may be loaded)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    polled = {(d.name, p.parameter, p.index) for d in runtime.drives.values() for p in d.polls}
    while loop.time() < end:
        lines = runtime.snapshot.lines
        up = lines and all(lines.values()) and len(lines) == len(runtime.runners)
        # The API's view (what a write is checked against), told after the planner's.
        described = not any(d.pending for d in runtime.snapshot.decoding.values())
        if up and described and polled <= runtime.snapshot.readings.keys():
            return
        await asyncio.sleep(0.01)
    raise AssertionError(f"lines not up after {timeout} s: {dict(runtime.snapshot.lines)}")


@pytest.fixture
def caplog_all(caplog: pytest.LogCaptureFixture) -> pytest.LogCaptureFixture:
    caplog.set_level(logging.DEBUG)
    return caplog
