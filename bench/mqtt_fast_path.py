"""The values' fast path, measured against the public API it could use instead: CPU per
QoS 0 value handed to a local mosquitto (started here, as ``bench/mqtt_publish.py`` does),
at plant scale (10,080 values: 4 lines x 126 drives x 20 values), until the client's
socket took them all. Three ways, side by side in each round (the machine's load falls
on all three alike), median of ``--repeat`` rounds:

- **batched** (what pkwbus does): :meth:`Connection.publish_values`, the PUBLISH packets
  of a slice built by pkwbus and handed to paho's socket writer as one entry of its queue
  (paho's ``_packet_queue``, not public);
- **paho publish**: paho's public ``Client.publish`` per value (what
  :meth:`Connection.publish_nowait` calls; aiomqtt offers no call that does not await);
- **aiomqtt publish**: aiomqtt's public ``await client.publish(...)`` per value.

    .venv/bin/python -m bench.mqtt_fast_path [--values 10080] [--repeat 7]
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import tempfile
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from prometheus_client import CollectorRegistry

from bench._measure import markdown_table
from bench.mqtt_publish import mosquitto
from pkwbus.service.mqtt.connection import Connection, publish_head
from pkwbus.service.mqtt.metrics import MqttMetrics
from pkwbus.service.mqtt.output import SLICE


async def drained(connection: Connection) -> None:
    client = connection._client
    while client is not None and client._client._out_packet:
        await asyncio.sleep(0)


async def measure(count: int, repeat: int) -> dict[str, list[float]]:
    topics = [f"pkwbus/line{i % 4}/fan{i // 80:03d}/16-{i % 20:02d}" for i in range(count)]
    payload = b'{"value": 49.87, "unit": "Hz", "quality": "good", "at": 1764370000.125}'
    heads = [publish_head(t) for t in topics]
    with tempfile.TemporaryDirectory() as tmp, mosquitto(Path(tmp)) as port:
        connection = Connection("127.0.0.1", port, username=None, password=None,
                                status_topic="pkwbus/status",
                                metrics=MqttMetrics(CollectorRegistry()))  # fmt: skip
        connection.start()
        await asyncio.wait_for(connection.connected.wait(), 20)
        client = connection._client
        assert client is not None

        async def batched() -> None:
            for at in range(0, count, SLICE):
                part = [(h, payload) for h in heads[at : at + SLICE]]
                assert connection.publish_values(part)

        async def paho() -> None:
            for topic in topics:
                assert connection.publish_nowait(topic, payload)

        async def aio() -> None:
            for topic in topics:
                await client.publish(topic, payload, 0)

        ways: dict[str, Callable[[], Awaitable[None]]] = {
            "batched (_packet_queue)": batched,
            "paho publish (public)": paho,
            "aiomqtt publish (public)": aio,
        }
        found: dict[str, list[float]] = {name: [] for name in ways}
        for _ in range(repeat + 1):
            for name, way in ways.items():
                await drained(connection)
                t0 = time.process_time()
                await way()
                await drained(connection)
                found[name].append((time.process_time() - t0) / count)
        await connection.stop()
    return {name: xs[1:] for name, xs in found.items()}  # the first round made the caches


def run(count: int = 4 * 126 * 20, repeat: int = 7) -> dict[str, Any]:
    """The figures as a table (``bench/run_all.py``)."""
    found = asyncio.run(measure(count, repeat))
    first = statistics.median(next(iter(found.values())))
    rows = [
        {"way": name, "median": statistics.median(xs) * 1e6, "min": min(xs) * 1e6,
         "times": statistics.median(xs) / first}
        for name, xs in found.items()
    ]  # fmt: skip
    table = markdown_table(
        rows, {"way": "way", "median": "CPU µs per value (median)", "min": "min",
               "times": "× the batched path"}, digits=2,
    )  # fmt: skip
    return {"table": table + f"\n{count} values a round, {repeat} rounds.\n", "measured": found}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--values", type=int, default=4 * 126 * 20)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    print(run(args.values, args.repeat)["table"])


if __name__ == "__main__":
    main()
