"""The MQTT output of `pkwbus run` (a subprocess on simulated FC drives on TCP) against a
real mosquitto with a password file and an ACL: values and the retained statuses seen by
a subscriber; Home Assistant's device configs as the golden files say; the will
``offline`` after kill -9; the broker stopped while drives trip, then every event
delivered once, in order, marked replayed."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import subprocess
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiomqtt
import httpx
import pytest

from pkwbus.sim import ModelConfig, SimTiming, Simulator
from tests.reliability.service import start_run
from tests.service.mqtt.broker import MOSQUITTO, USERS, Broker, mosquitto

GOLDEN = Path(__file__).parent / "golden"
REGENERATE = os.environ.get("PKWBUS_REGENERATE_GOLDEN") == "1"
TIMEOUT = 60.0  # generous: a loaded 2-core machine
STEADY = ModelConfig(warning_rate=0.0, trip_rate=0.0)  # only the trips a test makes

ACL = """\
user pkwbus
topic readwrite pkwbus/#
topic readwrite homeassistant/#

user scada
topic read #
topic write homeassistant/status
"""


@dataclass
class Seen:
    """What a subscriber got: (topic, payload, retain) each, in order."""

    messages: list[tuple[str, bytes, bool]] = field(default_factory=list)

    def on(self, topic: str) -> list[bytes]:
        return [p for t, p, _ in self.messages if t == topic]

    def under(self, suffix: str) -> list[tuple[str, bytes]]:
        return [(t, p) for t, p, _ in self.messages if t.endswith(suffix)]


@contextlib.asynccontextmanager
async def subscriber(broker: Broker, *topics: str) -> AsyncIterator[Seen]:
    """A client of the plant (account ``scada``) subscribed to ``topics``, connecting
    until the broker answers."""
    seen = Seen()
    loop = asyncio.get_running_loop()
    end = loop.time() + TIMEOUT
    while True:
        client = aiomqtt.Client(
            broker.host,
            broker.port,
            username="scada",
            password=USERS["scada"],
            protocol=aiomqtt.ProtocolVersion.V5,
        )
        try:
            await client.__aenter__()
            break
        except aiomqtt.MqttError:
            assert loop.time() < end, "the broker did not answer"
            await asyncio.sleep(0.05)
    try:
        for topic in topics:
            await client.subscribe(topic, qos=1)

        async def listen() -> None:
            async for m in client.messages:
                payload = m.payload if isinstance(m.payload, bytes) else str(m.payload).encode()
                seen.messages.append((m.topic.value, payload, m.retain))

        task = asyncio.create_task(listen())
        try:
            yield seen
        finally:
            task.cancel()
            with contextlib.suppress(BaseException):
                await task
    finally:
        with contextlib.suppress(Exception):
            await client.__aexit__(None, None, None)


async def until(check: Callable[[], bool], what: str, seconds: float = TIMEOUT) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    while not check():
        assert loop.time() < end, f"not within {seconds} s: {what}"
        await asyncio.sleep(0.05)


def config(folder: Path, url: str, broker: Broker, *, only: int = 2, **mqtt: Any) -> Path:
    """The plant's configuration: drives fan1 and fan2 (``only=1``: fan1 alone)."""
    drives = [
        {
            "name": "fan1",
            "address": 1,
            "catalog": "danfoss-fc",
            "poll": [
                {"parameter": "16-13", "every": "200ms"},
                {"parameter": "16-14", "every": "200ms"},
                {"parameter": "15-01", "every": "1s"},
                {"parameter": "15-02", "every": "1s"},
            ],
        },
        {
            "name": "fan2",
            "address": 2,
            "catalog": "danfoss-fc",
            "poll": [{"parameter": "16-13", "every": "200ms"}],
        },
    ][:only]
    body = {
        "audit_db": str(folder / "audit.sqlite"),
        "mqtt": {
            "url": f"mqtt://{broker.host}:{broker.port}",
            "username_env": "T_MQTT_USER",
            "password_env": "T_MQTT_PASSWORD",
            # Values unchanged on the steady drives come at each heartbeat: the shortest
            # the configuration allows, so that a wait for a few values is a short one.
            "values": {"deadband": 0, "heartbeat": "1s"},
            **mqtt,
        },
        "lines": [
            {
                "name": "line_fc",
                "port": url,
                "protocol": "fc",
                "baudrate": 115200,
                "timeout": "250ms",
                "alarms": "off",
                "settings": "off",
                "counters": "off",
                "events_every": "1s",
                "drives": drives,
            }
        ],
    }
    path = folder / "pkwbus.yaml"
    path.write_text(json.dumps(body, indent=1))
    return path


@contextlib.asynccontextmanager
async def plant() -> AsyncIterator[tuple[Simulator, str]]:
    sim = Simulator(
        "fc",
        [1, 2],
        timing=SimTiming(response_delay=0.001),
        seed=5,
        catalog="danfoss-fc",
        model=STEADY,
    )
    end = await sim.serve_tcp("127.0.0.1", 0)
    try:
        yield sim, end.url
    finally:
        await end.close()


@contextlib.asynccontextmanager
async def run(
    folder: Path, path: Path, ports: list[int] | None = None
) -> AsyncIterator[asyncio.subprocess.Process]:
    """``pkwbus run`` on the file ``path``; the port it listens on appended to ``ports``."""
    env = {**os.environ, "T_MQTT_USER": "pkwbus", "T_MQTT_PASSWORD": USERS["pkwbus"]}
    env.pop("PKWBUS_LISTEN", None)
    log = folder / "stderr.log"
    proc, port = await start_run(["run", "--config", str(path)], log, env=env, cwd=folder)
    if ports is not None:
        ports.append(port)
    try:
        yield proc
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGTERM)
        await asyncio.wait_for(proc.wait(), TIMEOUT)
        assert "Traceback" not in log.read_text(), log.read_text()


def golden(name: str, payload: bytes) -> None:
    """``payload`` (JSON) is the golden file ``name``; written anew with
    PKWBUS_REGENERATE_GOLDEN=1 (then reviewed against Home Assistant's schema)."""
    path = GOLDEN / name
    shown = json.dumps(json.loads(payload), indent=2, sort_keys=True, ensure_ascii=False) + "\n"
    if REGENERATE:
        path.parent.mkdir(exist_ok=True)
        path.write_text(shown, encoding="utf-8")
    assert shown == path.read_text(encoding="utf-8"), f"{name} differs from its golden file"


async def test_values_statuses_and_discovery(tmp_path: Path) -> None:
    with mosquitto(tmp_path / "broker", ACL) as broker:
        async with plant() as (_, url), subscriber(broker, "pkwbus/#", "homeassistant/#") as seen:
            path = config(tmp_path, url, broker)
            async with run(tmp_path, path):
                value = "pkwbus/line_fc/fan1/value/16-13"
                await until(lambda: len(seen.on(value)) >= 3, "values of 16-13")
                await until(lambda: b"online" in seen.on("pkwbus/line_fc/fan1/status"), "status")
                await until(
                    lambda: bool(
                        seen.on("homeassistant/device/pkwbus_line_fc_fan1/config")
                        and seen.on("homeassistant/device/pkwbus_line_fc_fan2/config")
                    ),
                    "discovery",
                )
                assert seen.on("pkwbus/status")[0] == b"online"
                got = json.loads(seen.on(value)[-1])
                assert set(got) == {"v", "raw", "unit", "ts", "q"}
                assert got["unit"] == "Hz" and got["q"] == "good"
                assert isinstance(got["v"], int | float) and isinstance(got["raw"], int)
                # Home Assistant comes online: the configs are sent again.
                n = len(seen.on("homeassistant/device/pkwbus_line_fc_fan1/config"))
                async with aiomqtt.Client(
                    broker.host, broker.port, username="scada", password=USERS["scada"]
                ) as ha:
                    await ha.publish("homeassistant/status", "online")
                await until(
                    lambda: len(seen.on("homeassistant/device/pkwbus_line_fc_fan1/config")) > n,
                    "discovery again",
                )
                for drive in ("fan1", "fan2"):
                    topic = f"homeassistant/device/pkwbus_line_fc_{drive}/config"
                    golden(f"{drive}.json", seen.on(topic)[-1])
        # A new subscriber gets the retained statuses and configs.
        async with subscriber(broker, "pkwbus/#", "homeassistant/#") as late:
            await until(lambda: late.on("pkwbus/status") == [b"offline"], "offline at the stop")
            retained = {t for t, _, r in late.messages if r}
            assert "pkwbus/line_fc/fan1/status" in retained
            assert "homeassistant/device/pkwbus_line_fc_fan1/config" in retained
            assert not any("/value/" in t for t in retained)  # values are never retained


async def test_a_reload_removes_a_drive_from_home_assistant(tmp_path: Path) -> None:
    config_topic = "homeassistant/device/pkwbus_line_fc_fan2/config"
    with mosquitto(tmp_path / "broker", ACL) as broker:
        async with plant() as (_, url), subscriber(broker, "pkwbus/#", "homeassistant/#") as seen:
            path = config(tmp_path, url, broker)
            async with run(tmp_path, path) as proc:
                await until(lambda: bool(seen.on(config_topic)), "fan2's config")
                config(tmp_path, url, broker, only=1)
                proc.send_signal(signal.SIGHUP)
                await until(lambda: seen.on(config_topic)[-1:] == [b""], "fan2's config emptied")
                assert seen.on("pkwbus/line_fc/fan2/status")[-1] == b""
                n = len(seen.on("pkwbus/line_fc/fan1/value/16-13"))
                await until(
                    lambda: len(seen.on("pkwbus/line_fc/fan1/value/16-13")) > n + 2,
                    "fan1's values go on",
                )
                gone = len(seen.on("pkwbus/line_fc/fan2/value/16-13"))
                await asyncio.sleep(1.0)
                assert len(seen.on("pkwbus/line_fc/fan2/value/16-13")) == gone


async def test_the_will_says_offline_after_kill_9(tmp_path: Path) -> None:
    with mosquitto(tmp_path / "broker", ACL) as broker:
        async with plant() as (_, url), subscriber(broker, "pkwbus/status") as seen:
            path = config(tmp_path, url, broker, homeassistant={"discovery": False})
            async with run(tmp_path, path) as proc:
                await until(lambda: seen.on("pkwbus/status")[-1:] == [b"online"], "online")
                proc.send_signal(signal.SIGKILL)
                await proc.wait()
                await until(lambda: seen.on("pkwbus/status")[-1:] == [b"offline"], "the will")


def _outbox(port: int) -> float | None:
    """The events pkwbus keeps until the broker acknowledges them, from its /metrics."""
    text = httpx.get(f"http://127.0.0.1:{port}/metrics", timeout=10).text
    for line in text.splitlines():
        if line.startswith("pkwbus_mqtt_outbox_messages "):
            return float(line.split()[1])
    return None


async def _outage(tmp_path: Path, seconds: float) -> None:
    """Drives trip before, during and after the broker is away (``seconds`` and 1.5 s for
    each trip): every event once, in order; those that waited marked replayed."""
    stack = contextlib.ExitStack()
    broker = stack.enter_context(mosquitto(tmp_path / "broker", ACL))
    again: subprocess.Popen[bytes] | None = None
    try:
        async with plant() as (sim, url):
            path = config(tmp_path, url, broker, homeassistant={"discovery": False})
            ports: list[int] = []
            async with run(tmp_path, path, ports):
                async with subscriber(broker, "pkwbus/+/+/event") as before:
                    await until(lambda: True, "")
                    await asyncio.sleep(2.0)  # the watch read the logs as they were
                    sim.trip(1, 13, value=1)
                    await until(lambda: len(before.messages) >= 1, "an event, live")
                    live = json.loads(before.messages[0][1])
                    assert live["code"] and "replayed" not in live
                    # Delivered is not yet acknowledged: an event whose PUBACK the broker's
                    # end did not reach pkwbus is sent again (at least once, QoS 1).
                    await until(lambda: _outbox(ports[0]) == 0, "the live event acknowledged")
                stack.close()  # the broker goes away
                codes = [(1, 14), (2, 16), (1, 30)]
                step = seconds / (len(codes) + 1)
                for address, code in codes:
                    await asyncio.sleep(step)
                    sim.trip(address, code, value=address)
                    await asyncio.sleep(1.5)  # each trip found by its own watch
                await asyncio.sleep(step)
                assert MOSQUITTO is not None
                conf = tmp_path / "broker" / "mosquitto.conf"
                again = subprocess.Popen(
                    [MOSQUITTO, "-c", str(conf)],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                )
                async with subscriber(broker, "pkwbus/+/+/event") as after:
                    await until(lambda: len(after.messages) >= 3, "the events kept")
                    await asyncio.sleep(3.0)  # nothing more comes
                    got = [json.loads(p) for _, p, _ in after.messages]
        drives = [(e["drive"], e["value"]) for e in got if e["kind"] != "warning"]
        assert drives == [("fan1", 1), ("fan2", 2), ("fan1", 1)], got
        assert all(e.get("replayed") is True for e in got)
        assert len({json.dumps(e, sort_keys=True) for e in got}) == len(got)  # each once
    finally:
        stack.close()
        if again is not None:
            again.kill()
            again.wait()


async def test_events_wait_through_a_broker_outage(tmp_path: Path) -> None:
    # The broker is away some 5 s (three trips, each given 1.5 s to be found), and back
    # before the client's third reconnect attempt (after 1, 2 and 4 s of back-off, each
    # +-20 %: 5.6 s at the earliest), so little of the test is spent waiting for it;
    # the 30 s form (make test-long) waits through the longer back-offs.
    await _outage(tmp_path, 0.4)


@pytest.mark.long
async def test_events_wait_through_a_30_s_broker_outage(tmp_path: Path) -> None:
    await _outage(tmp_path, 30.0)


async def test_a_site_prefix_has_its_own_device_ids_and_its_stale_configs_are_emptied(
    tmp_path: Path,
) -> None:
    """Under ``pkwbus/hall-a`` the device ids carry the site. A config of pkwbus's under that
    prefix for no drive of the service now (here: the id fan1 had before the site was in
    it) is emptied; another site's and another program's are left as they are."""
    ours = "homeassistant/device/pkwbus_hall-a_line_fc_fan1/config"
    stale = "homeassistant/device/pkwbus_line_fc_fan1/config"
    other_site = "homeassistant/device/pkwbus_hall-b_line_fc_fan1/config"
    foreign = "homeassistant/device/boiler/config"

    def doc(origin: str, status: str) -> bytes:
        body = {"origin": {"name": origin}, "availability": [{"topic": status}]}
        return json.dumps(body).encode()

    with mosquitto(tmp_path / "broker", ACL) as broker:
        async with aiomqtt.Client(
            broker.host, broker.port, username="pkwbus", password=USERS["pkwbus"]
        ) as client:
            for topic, payload in ((stale, doc("pkwbus", "pkwbus/hall-a/status")),
                                   (other_site, doc("pkwbus", "pkwbus/hall-b/status")),
                                   (foreign, doc("boiler", "pkwbus/hall-a/status"))):  # fmt: skip
                await client.publish(topic, payload, qos=1, retain=True)
        async with plant() as (_, url), subscriber(broker, "homeassistant/#") as seen:
            path = config(tmp_path, url, broker, prefix="pkwbus/hall-a")
            async with run(tmp_path, path):
                await until(lambda: bool(seen.on(ours)), "fan1's config under its site's id")
                await until(lambda: seen.on(stale)[-1:] == [b""], "the stale config emptied")
        async with subscriber(broker, "homeassistant/#") as late:
            await until(lambda: ours in {t for t, _, r in late.messages if r}, "retained")
            retained = {t for t, _, r in late.messages if r}
            assert stale not in retained
            assert {other_site, foreign} <= retained
