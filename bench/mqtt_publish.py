"""MQTT publishing at plant scale, beside the scrape: CPU per value published, at 10,080
values (4 lines x 126 drives x 20 values), against a local mosquitto.

The service's runtime is built as ``bench/scrape.py`` builds it (``assemble`` from the
benchmark configuration, no line running; readings land as a line's snapshot writer
lands them: into the snapshot, then ``ValueLanded`` to the outputs list). The MQTT
output is added to that list as ``pkwbus run`` adds it, connected to a mosquitto this
script starts on a free loopback port (anonymous, in a temp dir, killed at the end).

Timed, in CPU time of this process (the broker's is its own), median of ``--repeat``:

- **on change**: every value lands anew (a third with another value, deadband 0: those
  are published), through the whole outputs list, until the output's task has handed
  them to the socket; minus the same landing without the MQTT output; per value
  published;
- **heartbeat**: one pass publishing every value (with its quality); per value;
- **scrape**: ``exposition.render(registry)`` after a quarter of the values landed
  anew (what ``GET /metrics`` awaits); per value in the scrape.

    .venv/bin/python -m bench.mqtt_publish [--lines 4] [--drives 126] [--repeat 7]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from bench._measure import markdown_table
from bench.scrape import SHARE, Plant, build
from pkwbus import link
from pkwbus.service.config.mqtt import Mqtt
from pkwbus.service.metrics.exposition import render
from pkwbus.service.mqtt.connection import Connection
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.outbox import Outbox
from pkwbus.service.mqtt.output import MqttOutput


@contextlib.contextmanager
def mosquitto(folder: Path) -> Iterator[int]:
    binary = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not Path(binary).exists():
        sys.exit("mosquitto is not installed (Debian: apt-get install mosquitto)")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    conf = folder / "mosquitto.conf"
    user = subprocess.run(["id", "-un"], capture_output=True, text=True).stdout.strip()
    conf.write_text(
        f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n"
        f"user {user}\nmax_queued_messages 100000\n"
    )
    proc = subprocess.Popen(
        [binary, "-c", str(conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        end = time.monotonic() + 20
        while True:
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.5):
                break
            if time.monotonic() > end or proc.poll() is not None:
                sys.exit("mosquitto did not start")
            time.sleep(0.05)
        yield port
    finally:
        proc.kill()
        proc.wait()


async def drained(output: MqttOutput) -> None:
    """Until the output's task has published what landed and the client's socket took it."""
    while output._pending or output._wake.is_set():
        await asyncio.sleep(0)
    client = output.connection._client
    while client is not None and client._client._out_packet:
        await asyncio.sleep(0)


async def measure(lines: int, drives: int, repeat: int) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp, mosquitto(Path(tmp)) as port:
        plant: Plant = await build(lines, drives, False, tmp)
        runtime = plant.runtime
        settings = Mqtt.model_validate(
            {
                "url": f"mqtt://127.0.0.1:{port}",
                "homeassistant": {"discovery": False},
                "values": {"heartbeat": "24h"},
            }
        )
        metrics = MqttMetrics(runtime.registry)
        connection = Connection(
            "127.0.0.1",
            port,
            username=None,
            password=None,
            status_topic="pkwbus/status",
            metrics=metrics,
        )
        outbox = Outbox(Path(tmp) / "outbox.sqlite", 1 << 20, 3600.0)
        output = MqttOutput(settings, runtime, connection, outbox, metrics)
        base = runtime.outputs.items
        output.start()
        await asyncio.wait_for(connection.connected.wait(), 20)
        await asyncio.sleep(0.5)
        values = len(plant.keys)
        sent = metrics.sent["value"]

        without, with_mqtt, per_beat, per_scrape = [], [], [], []
        changes: list[float] = []
        for _ in range(repeat + 1):
            runtime.outputs.swap(base)
            t0 = time.process_time()
            plant.land(1)
            without.append(time.process_time() - t0)

            runtime.outputs.swap([*base, output])
            before = sent._value.get()
            t0 = time.process_time()
            plant.land(1)
            await drained(output)
            with_mqtt.append(time.process_time() - t0)
            published = sent._value.get() - before
            changes.append(published)

            for topic in output.topics.topics.values():
                if topic is not None:
                    topic.sent = float("-inf")
            t0 = time.process_time()
            beat = await output.beat()
            await drained(output)
            per_beat.append((time.process_time() - t0) / max(beat, 1))

            plant.land(SHARE)
            t0 = time.process_time()
            text = await render(runtime.registry)
            per_scrape.append((time.process_time() - t0) / values)
        await output.stop()

    def med(xs: list[float]) -> float:
        return statistics.median(xs[1:]) * 1e6  # the first made the caches

    extra = statistics.median(with_mqtt[1:]) - statistics.median(without[1:])
    rows = [
        {"what": "MQTT on change (landing with - without, per value published)",
         "us": extra / statistics.median(changes[1:]) * 1e6},
        {"what": "MQTT heartbeat, per value published", "us": med(per_beat)},
        {"what": "scrape render, per value in GET /metrics", "us": med(per_scrape)},
    ]  # fmt: skip
    table = markdown_table(rows, {"what": "CPU per value", "us": "µs (median)"}, digits=2)
    note = (
        f"\n{values} values ({lines} lines x {drives} drives); a landing publishes "
        f"{published} (a third changes), a heartbeat {beat}; the scrape {len(text)} bytes."
    )
    return {"rows": rows, "table": table + note}


def run(lines: int = 4, drives: int = 126, repeat: int = 7) -> dict[str, Any]:
    return link.run(measure(lines, drives, repeat))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, default=4)
    parser.add_argument("--drives", type=int, default=126)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    print(run(args.lines, args.drives, args.repeat)["table"])


if __name__ == "__main__":
    main()
