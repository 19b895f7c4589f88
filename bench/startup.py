"""Start-up: what reading the drives' own descriptions (AK 4) costs at 126 drives x 20
parameters, and how long before every value is in the snapshot.

One line of 126 simulated FC drives (another process, pty, wire timing at
115200 baud, 2 ms response delay), twenty polled parameters each, two of
them writable, every parameter polled every second (a full line). Three
starts of the service in this process: ``describe: off`` (the catalog
alone), ``describe: auto`` with no description file (every drive is asked),
and ``describe: auto`` again with the file the second start wrote (a
restart). For each: seconds from the start until every polled parameter has
a value, the telegrams exchanged by then, and the identity and description
requests among them.

    .venv/bin/python -m bench.startup [--drives 126]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import tempfile
import time
from pathlib import Path
from typing import Any

from bench._common import service_config, sim_process
from bench._measure import markdown_table
from bench.scale import BAUD, DELAY, PARAMETERS
from pkwbus import link
from pkwbus.master.planning import describing
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.assembly.description_file import DescriptionFile
from pkwbus.service.config import parse_config

_steps = {"identity": 0, "description": 0}
_next_request = describing.DriveDescriber.next_request


def _counted(self: describing.DriveDescriber, now: float) -> describing.DescribeStep | None:
    step = _next_request(self, now)
    if step is not None:
        _steps["identity" if step.identity else "description"] += 1
    return step


describing.DriveDescriber.next_request = _counted  # type: ignore[method-assign]


async def _start(text: str, kept: DescriptionFile | None, polled: int) -> dict[str, Any]:
    _steps.update(identity=0, description=0)
    runtime = await build_runtime(parse_config(text, environ={}), kept)
    t0 = time.perf_counter()
    await runtime.start()
    try:
        deadline = t0 + 600.0
        while len(runtime.snapshot.readings) < polled and time.perf_counter() < deadline:
            await asyncio.sleep(0.05)
        took = time.perf_counter() - t0
        telegrams = sum(t.telegrams for t in runtime.snapshot.totals.values())
        values = len(runtime.snapshot.readings)
    finally:
        await runtime.stop()
    return {
        "values": values,
        "seconds": took,
        "telegrams": telegrams,
        "identity": _steps["identity"],
        "descriptions": _steps["description"],
    }


def measure(drives: int) -> list[dict[str, Any]]:
    polled = drives * len(PARAMETERS)
    rows = []
    with contextlib.ExitStack() as stack, tempfile.TemporaryDirectory() as tmp:
        port = stack.enter_context(
            sim_process("fc", f"1-{drives}", response_delay=DELAY, baudrate=BAUD,
                        wire_timing=True, catalog="danfoss-fc")
        )  # fmt: skip
        text = service_config([port], drives=drives, pnus=PARAMETERS, every="1s", baudrate=BAUD,
                              audit_db=f"{tmp}/audit.sqlite")  # fmt: skip
        off = text.replace("        catalog: danfoss-fc\n", "        catalog: danfoss-fc\n"
                           "        describe: off\n")  # fmt: skip
        path = Path(tmp) / "audit.sqlite.descriptions.json"
        for name, config, kept in (
            ("describe: off", off, None),
            ("auto, first start", text, DescriptionFile(path)),
            ("auto, restart", text, None),
        ):
            if kept is None and name.endswith("restart"):
                kept = DescriptionFile(path)
            row = link.run(_start(config, kept, polled))
            rows.append({"start": name, **row})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=int, default=126)
    args = parser.parse_args()
    rows = measure(args.drives)
    print(markdown_table(rows, ["start", "values", "seconds", "telegrams", "identity",
                                "descriptions"], digits=1))  # fmt: skip


if __name__ == "__main__":
    main()
