"""The lines' throughput with MQTT on, beside the same without it, in one run (issue
"MQTT", "Done when": unchanged, >= 98 %).

``pkwbus run`` in its own process, as a plant runs it: 4 simulated lines (one simulator
process each, pty, wire timing at 115200 baud, 2 ms response delay) x 126 Danfoss FC
drives x benchmark 6's twenty parameters, each polled every second, far more than a line
carries: the lines run at full load, so any CPU the MQTT output takes from the event
loop shows as fewer telegrams. With MQTT, the service publishes to a mosquitto this
script starts on a free loopback port (anonymous, in a temp dir, killed at the end):
every value on change (deadband 0) and every value at least every 10 s (a heartbeat far
shorter than the README's example of 5 min), statuses, and Home Assistant discovery.

Rounds alternate a service without ``mqtt:`` and one with it (a fresh process each,
the same simulators); each is measured once every polled value has landed once and the
start is over: telegrams/s of all lines from the service's ``pkwbus_telegrams_total``
over ``--seconds``, and, with MQTT, the values published per second
(``pkwbus_mqtt_messages_total{kind="value"}``). The ratio with / without of each round
and their median.

    .venv/bin/python -m bench.mqtt_throughput [--rounds 3] [--seconds 20]
"""

from __future__ import annotations

import argparse
import contextlib
import re
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from bench._common import pkwbus_run, service_config, telegrams_in
from bench._measure import markdown_table
from bench.mqtt_publish import mosquitto
from bench.scale import BAUD, PARAMETERS, fc_lines

VALUES_SENT = re.compile(r'^pkwbus_mqtt_messages_total\{kind="value"\} ([0-9.e+]+)$', re.M)
PARAMETER_VALUES = re.compile(r"^pkwbus_parameter_value\{", re.M)

GOAL = 0.98


def _counts(client: httpx.Client) -> tuple[float, float, int]:
    """(telegrams of all lines, MQTT values sent, parameter values shown) now."""
    text = client.get("/metrics").text
    sent = VALUES_SENT.search(text)
    return (
        telegrams_in(text),
        float(sent.group(1)) if sent else 0.0,
        len(PARAMETER_VALUES.findall(text)),
    )


def _one(
    folder: Path, ports: list[str], broker: int | None, seconds: float, settle: float
) -> dict[str, Any]:
    """One service's telegrams/s (and MQTT values/s) at full load, once settled."""
    text = service_config(
        ports, drives=126, pnus=PARAMETERS, every="1s", baudrate=BAUD,
        audit_db=str(folder / "audit.sqlite"),
    )  # fmt: skip
    if broker is not None:
        text = (
            f"mqtt:\n  url: mqtt://127.0.0.1:{broker}\n  prefix: pkwbus\n"
            "  values: {deadband: 0, heartbeat: 10s}\n"
            "  homeassistant: {discovery: true, prefix: homeassistant}\n" + text
        )
    with (
        pkwbus_run(text, folder, "mqtt" if broker else "quiet", stop_timeout=10.0) as service,
        httpx.Client(base_url=service.base, timeout=60) as client,
    ):
        polled = len(ports) * 126 * len(PARAMETERS)
        deadline = time.monotonic() + settle
        while True:
            with contextlib.suppress(httpx.TransportError):
                if _counts(client)[2] >= polled:
                    break
            if time.monotonic() > deadline or service.process.poll() is not None:
                raise RuntimeError(f"not every value landed within {settle:.0f} s")
            time.sleep(1.0)
        time.sleep(2.0)  # the first publication of everything is over
        n0, s0, _ = _counts(client)
        t0 = time.monotonic()
        time.sleep(seconds)
        n1, s1, _ = _counts(client)
        t1 = time.monotonic()
    tracebacks = service.log.read_text(errors="replace").count("Traceback")
    if tracebacks:
        raise RuntimeError(f"the service logged {tracebacks} traceback(s): see {service.log}")
    return {"telegrams_s": (n1 - n0) / (t1 - t0), "values_s": (s1 - s0) / (t1 - t0)}


def run(
    rounds: int = 3, seconds: float = 20.0, lines: int = 4, settle: float = 120.0
) -> dict[str, Any]:
    rows: list[dict[str, Any]] = []
    with contextlib.ExitStack() as stack:
        folder = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        broker = stack.enter_context(mosquitto(folder))
        ports = stack.enter_context(fc_lines(lines, 126))
        for i in range(rounds):
            quiet = _one(folder, ports, None, seconds, settle)
            loud = _one(folder, ports, broker, seconds, settle)
            rows.append({
                "round": i + 1,
                "quiet": quiet["telegrams_s"],
                "mqtt": loud["telegrams_s"],
                "ratio": loud["telegrams_s"] / quiet["telegrams_s"],
                "values_s": loud["values_s"],
            })  # fmt: skip
            print(rows[-1], flush=True)
    median = statistics.median(r["ratio"] for r in rows)
    rows.append({
        "round": "median",
        "quiet": statistics.median(r["quiet"] for r in rows),
        "mqtt": statistics.median(r["mqtt"] for r in rows),
        "ratio": median,
        "values_s": statistics.median(r["values_s"] for r in rows),
    })  # fmt: skip
    table = markdown_table(
        rows,
        {
            "round": "round",
            "quiet": "telegrams/s, no MQTT",
            "mqtt": "telegrams/s, MQTT on",
            "ratio": "MQTT on / off",
            "values_s": "values published/s",
        },
        digits=3,
    )
    verdict = (
        f"\nMedian ratio {median:.3f}: goal >= {GOAL} {'met' if median >= GOAL else 'NOT met'}."
    )
    return {"rows": rows, "table": table + verdict, "ratio": median}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--lines", type=int, default=4)
    parser.add_argument("--settle", type=float, default=120.0)
    args = parser.parse_args()
    print(run(args.rounds, args.seconds, args.lines, args.settle)["table"])


if __name__ == "__main__":
    main()
