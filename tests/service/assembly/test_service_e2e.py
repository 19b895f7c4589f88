"""The service end to end over simulated drives: values, counters, health, readiness, shutdown."""

from __future__ import annotations

import asyncio
import logging
import re
import signal
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
from prometheus_client import generate_latest
from prometheus_client.parser import text_string_to_metric_families

from pkwbus.catalog import load_catalog
from pkwbus.catalog.description import ParameterDescription
from pkwbus.protocol.pzd import ref_to_percent
from pkwbus.protocol.values import ValueType, decode_value
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.service.http.api import create_app
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimFaults, SimTiming, Simulator
from tests.master.conftest import until
from tests.reliability.service import start_run


def samples(runtime: Runtime) -> dict[tuple[str, frozenset[tuple[str, str]]], float]:
    text = generate_latest(runtime.registry).decode()
    out = {}
    for family in text_string_to_metric_families(text):
        for s in family.samples:
            out[(s.name, frozenset(s.labels.items()))] = s.value
    return out


def sample(runtime: Runtime, name: str, **labels: str) -> float | None:
    want = set(labels.items())
    for (n, lab), value in samples(runtime).items():
        if n == name and want <= lab:
            return value
    return None


@asynccontextmanager
async def running(config_text: str) -> AsyncIterator[Runtime]:
    config = parse_config(config_text, environ={})
    runtime = await build_runtime(config)
    await runtime.start()
    try:
        yield runtime
    finally:
        await runtime.stop()


def fc_line(name: str, url: str, drives: str, *, timeout: str = "50ms", retries: int = 2) -> str:
    return f"""
  - name: {name}
    port: "{url}"
    protocol: fc
    baudrate: 115200
    timeout: {timeout}
    retries: {retries}
    drives:
{drives}"""


async def test_metrics_carry_the_simulators_values_scaled() -> None:
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.001), catalog="danfoss-fc")
    sim.drives[1].set_value(341, 1234)  # 3-41 ramp up time, conversion -2: 12.34 s
    sim.drives[2].set_value(341, 77)
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = """
      - name: fan_a
        address: 1
        catalog: danfoss-fc
        poll: [{parameter: "3-41", every: 50ms}, {parameter: "16-13", every: 50ms}]
      - name: fan_b
        address: 2
        catalog: danfoss-fc
        poll: [{parameter: "3-41", every: 50ms}, {parameter: "16-30", every: 50ms}]"""
    try:
        async with running("lines:" + fc_line("l1", server.url, drives)) as runtime:
            # every polled value in, and the status word of fan_b (waited for, not timed:
            # the machine may be loaded)
            wanted = (("fan_a", "3-41"), ("fan_b", "3-41"), ("fan_a", "16-13"), ("fan_b", "16-30"))
            await until(
                lambda: (
                    all(
                        sample(runtime, "pkwbus_parameter_value", drive=d, parameter=p) is not None
                        for d, p in wanted
                    )
                    and sample(runtime, "pkwbus_drive_status_word", drive="fan_b") is not None
                ),
                timeout=30.0,
            )
            got_a = sample(runtime, "pkwbus_parameter_value", drive="fan_a", parameter="3-41")
            got_b = sample(runtime, "pkwbus_parameter_value", drive="fan_b", parameter="3-41")
            freq = sample(runtime, "pkwbus_parameter_value", drive="fan_a", parameter="16-13")
            dc = sample(runtime, "pkwbus_parameter_value", drive="fan_b", parameter="16-30")
            up = sample(runtime, "pkwbus_drive_up", drive="fan_a")
            info = sample(
                runtime,
                "pkwbus_parameter_info",
                drive="fan_a",
                parameter="3-41",
                unit="s",
                pnu="341",
                type="u32",
            )
            stamp = sample(
                runtime,
                "pkwbus_parameter_last_update_timestamp_seconds",
                drive="fan_a",
                parameter="3-41",
            )
            line_up = sample(runtime, "pkwbus_line_up", line="l1")
            status = sample(runtime, "pkwbus_drive_status_word", drive="fan_b")
    finally:
        await server.close()
    assert (got_a, got_b) == (12.34, 0.77)
    spec = load_catalog("danfoss-fc").get(1613)
    assert spec is not None and spec.type is not None
    # A live value: it must decode from what drive 1 can produce (frequency ramps in 0.1 Hz).
    expected = decode_value(
        sim.drives[1].value(1613),
        ValueType(spec.type).width,  # type: ignore[arg-type]
        ValueType(spec.type),
        ParameterDescription.from_spec(spec).scaling,
    )
    assert freq == pytest.approx(float(expected), abs=1.0)
    assert dc is not None and 400 < dc < 800
    assert (up, info, line_up) == (1.0, 1.0, 1.0)
    assert stamp is not None and stamp > 1.7e9
    assert status == sim.drives[2].status_word


@pytest.mark.parametrize("protocol", ["fc", "uss"])
async def test_the_main_actual_value_of_each_reply_is_exported_as_percent(protocol: str) -> None:
    """FC protocol: PCD 2 of a reply; USS: its second PZD word (HIW). 0x4000 = 100 %."""
    sim = Simulator(protocol, [1, 2], timing=SimTiming(response_delay=0.001), seed=4)
    for address, hz in ((1, 17.5), (2, 42.0)):
        model = sim.drives[address].model
        model.setpoint = model.frequency = hz  # a different value for each drive
    server = await sim.serve_tcp("127.0.0.1", 0)
    parameter = "3-41" if protocol == "fc" else "1120"
    drives = "\n".join(
        f"""      - name: d{a}
        address: {a}
        poll: [{{parameter: "{parameter}", every: 20ms}}]"""
        for a in (1, 2)
    )
    text = "lines:" + fc_line("l1", server.url, drives).replace(
        "protocol: fc", f"protocol: {protocol}"
    )
    mav = "pkwbus_drive_main_actual_percent"
    try:
        async with running(text) as runtime:
            for _ in range(1000):
                if len({sample(runtime, mav, drive=d) for d in ("d1", "d2")} - {None}) == 2:
                    break
                await asyncio.sleep(0.01)
        # stopped: every answer is accounted for, the drives still hold the latest one's
        got = {a: sample(runtime, mav, drive=f"d{a}") for a in (1, 2)}
    finally:
        await server.close()
    assert got[1] != got[2]
    for address in (1, 2):
        assert got[address] == ref_to_percent(sim.drives[address].mav)


async def test_fault_and_error_counters_match_what_the_simulator_did() -> None:
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.0), seed=3)
    sim.set_faults(2, SimFaults(corrupt=0.15, drop=0.1))
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = """
      - name: bad_pnu
        address: 1
        poll: [{parameter: "999", every: 20ms}]
      - name: noisy
        address: 2
        poll: [{parameter: "3-41", every: 10ms}]"""
    try:
        async with running("lines:" + fc_line("l1", server.url, drives, retries=5)) as runtime:
            await asyncio.sleep(1.0)
            # stop first so that every exchange is accounted for on both sides
        got = samples(runtime)
    finally:
        await server.close()
    stats = sim.stats.as_dict()

    def value(name: str, **labels: str) -> float:
        want = set(labels.items())
        return sum(v for (n, lab), v in got.items() if n == name and want <= lab)

    rejected = value("pkwbus_jobs_total", drive="bad_pnu", outcome="rejected")
    assert rejected > 10
    assert value("pkwbus_pkw_faults_total", drive="bad_pnu", fault_code="0") == rejected
    injected = stats["per_drive"]["2"]["injected"]
    assert injected["corrupt"] > 0 and injected["drop"] > 0
    assert (
        value("pkwbus_telegram_errors_total", drive="noisy", kind="checksum") == injected["corrupt"]
    )
    assert value("pkwbus_telegram_errors_total", drive="noisy", kind="timeout") == injected["drop"]
    assert value("pkwbus_telegrams_total", drive="noisy") == stats["per_drive"]["2"]["requests"]
    assert value("pkwbus_drive_up", drive="noisy") == 1.0


async def test_readyz_says_which_line_is_down(caplog: pytest.LogCaptureFixture) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0))
    server = await sim.serve_tcp("127.0.0.1", 0)
    drive = """
      - name: d{n}
        address: 1
        poll: [{{parameter: "3-41", every: 50ms}}]"""
    text = (
        "lines:"
        + fc_line("good", server.url, drive.format(n=1))
        + fc_line("gone", "socket://127.0.0.1:1", drive.format(n=2))
    )
    caplog.set_level(logging.INFO)
    try:
        async with running(text) as runtime:
            await asyncio.sleep(0.5)
            app = create_app(runtime)
            transport = httpx.ASGITransport(app=app)
            async with httpx.AsyncClient(transport=transport, base_url="http://t") as client:
                ready = await client.get("/readyz")
                health = await client.get("/healthz")
                drives = (await client.get("/api/v1/drives")).json()
    finally:
        await server.close()
    assert health.status_code == 200
    assert ready.status_code == 503
    assert ready.json()["lines"] == {"good": True, "gone": False}
    assert [d["name"] for d in drives] == ["d1", "d2"]
    # No catalog: the value is scaled as the drive describes the parameter (AK 4).
    assert drives[0]["values"][0]["value"] == sim.drives[1].params.number(341)
    failures = [r for r in caplog.records if "cannot open socket://127.0.0.1:1" in r.getMessage()]
    assert len(failures) == 1, "a port that stays down is reported once, not at every retry"


async def test_a_dead_drive_is_logged_once_down_and_once_back(
    caplog: pytest.LogCaptureFixture,
) -> None:
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.0))
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = """
      - name: ok
        address: 1
        poll: [{parameter: "3-41", every: 20ms}]
      - name: flaky
        address: 2
        poll: [{parameter: "3-41", every: 20ms}]"""
    caplog.set_level(logging.INFO)
    try:
        async with running("lines:" + fc_line("l1", server.url, drives, timeout="20ms")) as rt:
            sim.kill(2)
            await until(lambda: any("flaky is down" in r.getMessage() for r in caplog.records))
            down = sample(rt, "pkwbus_drive_up", drive="flaky")
            sim.revive(2)
            # the first probe comes 1 s after going down
            await until(lambda: sample(rt, "pkwbus_drive_up", drive="flaky") == 1.0, step=0.05)
            up = sample(rt, "pkwbus_drive_up", drive="flaky")
    finally:
        await server.close()
    assert (down, up) == (0.0, 1.0)
    went = [r for r in caplog.records if "drive flaky is down" in r.getMessage()]
    back = [r for r in caplog.records if "drive flaky answers again" in r.getMessage()]
    assert len(went) == 1 and len(back) == 1
    assert getattr(went[0], "drive", None) == "flaky" and getattr(went[0], "line", None) == "l1"


async def test_sigterm_stops_the_service_within_seconds(tmp_path: Path) -> None:
    config = tmp_path / "c.yaml"
    config.write_text(
        f"audit_db: {tmp_path / 'audit.sqlite'}\n"
        "lines:\n"
        "  - name: l1\n    port: sim://fc?drives=1,2\n    protocol: fc\n    baudrate: 19200\n"
        "    drives:\n"
        "      - {name: a, address: 1, poll: [{parameter: '16-13', every: 100ms}]}\n"
        "      - {name: b, address: 2, poll: [{parameter: '16-13', every: 100ms}]}\n"
    )
    log = tmp_path / "stderr.log"
    proc, _ = await start_run(["run", "--config", str(config)], log)  # a port of its own
    try:
        # a line is up: the service runs
        await until(lambda: re.search(r"port .* open", log.read_text()) is not None, 30)
        up = len(log.read_text())
        proc.send_signal(signal.SIGTERM)
        code = await asyncio.wait_for(proc.wait(), 5)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    said = log.read_text()
    assert code == 0, said
    assert "Traceback" not in said
    assert re.search(r"stopped", said[up:])


@pytest.fixture(autouse=True)
def _quiet(caplog: Any) -> None:
    caplog.set_level(logging.WARNING, logger="uvicorn")
