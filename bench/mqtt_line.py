"""Line throughput with MQTT on against without, at plant scale, side by side in one run.

The scale of benchmark 12 (``bench/plant_scale.py``, the README's plant): 4 simulated
lines (one simulator process each, pty, wire timing at 115200 baud, 2 ms response
delay) x 126 Danfoss FC drives x 20 values each polled every 20 s (10,080 values), the
service in this process. The MQTT output is attached as ``pkwbus run`` attaches it (the
``mqtt:`` section, Home Assistant discovery off), connected to a mosquitto this script
starts on a free loopback port (anonymous, in a temp dir, killed at the end).

Once every value has landed and the start's backlog has drained, ``--rounds`` rounds of
two windows of ``--seconds``: **off** (the MQTT output taken out of the outputs list:
nothing published) then **on** (put back: every changed value published, the
heartbeat). Telegrams/s per line from the lines' own counts, this process's CPU share,
the event loop's lag, the values published in the on windows. The figure: median
telegrams/s on / off (goal: at least 0.98), and each round's ratio.

    .venv/bin/python -m bench.mqtt_line [--rounds 3] [--seconds 20] [--settle 240]
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

from bench._common import machine, machine_note
from bench._measure import markdown_table
from bench.mqtt_publish import mosquitto
from bench.plant_scale import (
    DRIVES,
    EVERY,
    LINES,
    _settle,
    _window,
    plant_lines,
    plant_service,
)
from bench.scale import PARAMETERS
from pkwbus import link
from pkwbus.service.config import parse_config
from pkwbus.service.mqtt.output import attach

GOAL_RATIO = 0.98


async def _measure(
    ports: list[str], broker: int, drives: int, seconds: float, rounds: int, settle: float
) -> dict[str, Any]:
    extra = f"mqtt:\n  url: mqtt://127.0.0.1:{broker}\n  homeassistant: {{discovery: false}}\n"
    async with plant_service(ports, drives, extra) as (service, probe):
        runtime = service.runtime
        output = attach(parse_config(service.config_text), runtime, None)
        assert output is not None
        output.start()
        try:
            await asyncio.wait_for(output.connection.connected.wait(), 30.0)
            start = await _settle(runtime, settle)
            on = list(runtime.outputs.items)
            off = [o for o in on if o is not output]
            sent = output.metrics.sent["value"]
            found: dict[str, list[dict[str, Any]]] = {"off": [], "on": []}
            for _ in range(rounds):
                runtime.outputs.swap(off)
                found["off"].append(await _window(runtime, probe, seconds))
                runtime.outputs.swap(on)
                before = sent._value.get()
                window = await _window(runtime, probe, seconds)
                window["published_s"] = (sent._value.get() - before) / seconds
                found["on"].append(window)
        finally:
            await output.stop()  # the assembly's cleanup does it in the service
    return {"start": start, **found}


def measure(
    lines: int = LINES, drives: int = DRIVES, seconds: float = 20.0, rounds: int = 3,
    settle: float = 240.0,
) -> dict[str, Any]:  # fmt: skip
    with (
        tempfile.TemporaryDirectory() as tmp,
        mosquitto(Path(tmp)) as broker,
        plant_lines(lines, drives) as ports,
    ):
        return link.run(_measure(ports, broker, drives, seconds, rounds, settle))


def run(
    seconds: float = 20.0, rounds: int = 3, settle: float = 240.0, lines: int = LINES,
    drives: int = DRIVES,
) -> dict[str, Any]:  # fmt: skip
    before = machine()
    got = measure(lines, drives, seconds, rounds, settle)
    after = machine()
    rows: list[dict[str, object]] = []
    for n, (off, on) in enumerate(zip(got["off"], got["on"], strict=True), 1):
        rows.append({
            "round": str(n), "off": off["telegrams_s"], "on": on["telegrams_s"],
            "ratio": on["telegrams_s"] / off["telegrams_s"],
            "published": on["published_s"], "cpu_off": off["cpu"] * 100,
            "cpu_on": on["cpu"] * 100, "lag_off": off["lag_p99_ms"], "lag_on": on["lag_p99_ms"],
        })  # fmt: skip
    median_off = statistics.median(w["telegrams_s"] for w in got["off"])
    median_on = statistics.median(w["telegrams_s"] for w in got["on"])
    ratio = median_on / median_off
    rows.append({"round": "median", "off": median_off, "on": median_on, "ratio": ratio})
    table = markdown_table(
        rows,
        {"round": "round", "off": "telegrams/s per line, MQTT off", "on": "MQTT on",
         "ratio": "on / off", "published": "values published/s", "cpu_off": "CPU % off",
         "cpu_on": "CPU % on", "lag_off": "loop lag p99 ms off", "lag_on": "on"},
        digits=2,
    )  # fmt: skip
    table += (
        f"\nGoal: on / off at least {GOAL_RATIO:g}: "
        f"{'met' if ratio >= GOAL_RATIO else 'NOT met'} ({ratio:.3f}). {lines} lines × "
        f"{drives} drives × {len(PARAMETERS)} values every {EVERY:g} s, {seconds:g} s "
        f"windows, {rounds} rounds. {machine_note(before, after)}\n"
    )
    return {"rows": rows, "table": table, "measured": got, "ratio": ratio}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--settle", type=float, default=240.0)
    parser.add_argument("--lines", type=int, default=LINES)
    parser.add_argument("--drives", type=int, default=DRIVES)
    args = parser.parse_args()
    result = run(args.seconds, args.rounds, args.settle, args.lines, args.drives)
    print(result["table"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
