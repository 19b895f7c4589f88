"""The rooms one polled value crosses: which pkwbus modules run for each exchange on the
service path, and how often a call crosses from one module (and one layer) into another.

The service is built from a configuration as `pkwbus run` builds it (layout-free, as
bench/service_path.py), an FC line and a PROFIBUS DP line in turn, each against a
simulator in another process; for a window of exchanges in steady state every call of
a pkwbus function is traced (``sys.setprofile``: slow, so only the counts matter, not
the time). Printed per bus, per exchange: the modules that ran, the calls that crossed
into another module, into another layer (``protocol``, ``master``, ``service`` ...),
and the times the path came back into ``master`` from another layer.

    .venv/bin/python -m bench.value_path [--n 300] [--tree NAME] [--modules]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections import Counter
from types import FrameType
from typing import Any

from bench import service_path
from bench._common import sim_process
from bench._measure import markdown_table
from pkwbus import link
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config

PACKAGE = "pkwbus."


class Tracer:
    def __init__(self) -> None:
        self.modules: Counter[str] = Counter()
        self.crossings = 0
        self.layer_crossings = 0
        self.into_master = 0

    def __call__(self, frame: FrameType, event: str, arg: Any) -> None:
        if event != "call":
            return
        module = frame.f_globals.get("__name__", "")
        if not module.startswith(PACKAGE):
            return
        self.modules[module] += 1
        back = frame.f_back
        caller = back.f_globals.get("__name__", "") if back is not None else ""
        if not caller.startswith(PACKAGE) or caller == module:
            return
        self.crossings += 1
        layer, from_layer = module.split(".")[1], caller.split(".")[1]
        if layer != from_layer:
            self.layer_crossings += 1
            if layer == "master":
                self.into_master += 1


async def _trace(config_text: str, n: int) -> dict[str, Any]:
    runtime = await build_runtime(parse_config(config_text, environ={}))
    await runtime.start()
    tracer = Tracer()
    try:
        while service_path._telegrams(runtime) < 300:
            await asyncio.sleep(0.02)
        t0 = service_path._telegrams(runtime)
        sys.setprofile(tracer)
        try:
            while service_path._telegrams(runtime) - t0 < n:
                await asyncio.sleep(0.01)
        finally:
            sys.setprofile(None)
        count = service_path._telegrams(runtime) - t0
    finally:
        await runtime.stop()
    every = {m for m, c in tracer.modules.items() if c >= count * 0.5}  # in most exchanges
    return {
        "exchanges": count,
        "modules_in_most_exchanges": len(every),
        "calls_crossing_modules": tracer.crossings / count,
        "calls_crossing_layers": tracer.layer_crossings / count,
        "back_into_master": tracer.into_master / count,
        "modules": sorted(every),
    }


def fc(n: int) -> dict[str, Any]:
    with sim_process("fc", "1-3") as port:
        return link.run(_trace(service_path._fc_config(port), n))


def dp(n: int) -> dict[str, Any]:
    with service_path.dp_simulator() as pty:
        return link.run(_trace(service_path._dp_config(pty), n))


def run(n: int = 300) -> dict[str, Any]:
    """Both buses' figures, and their table (for run_all)."""
    rows = [{"bus": bus, **trace(n)} for bus, trace in (("FC", fc), ("PROFIBUS DP", dp))]
    table = markdown_table(
        rows,
        {
            "bus": "bus",
            "exchanges": "exchanges traced",
            "modules_in_most_exchanges": "modules run in most exchanges",
            "calls_crossing_modules": "calls into another module per exchange",
            "calls_crossing_layers": "into another layer",
            "back_into_master": "back into master",
        },
        digits=1,
    )
    return {"rows": rows, "table": table}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=300)
    parser.add_argument("--tree", default="this tree")
    parser.add_argument("--modules", action="store_true", help="list the modules too")
    args = parser.parse_args()
    for row in run(args.n)["rows"]:
        modules = row.pop("modules")
        bus = row.pop("bus")
        figures = ", ".join(
            f"{k} {v:.1f}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()
        )
        print(f"{args.tree} {bus}: {figures}")
        if args.modules:
            print("   " + " ".join(m.removeprefix(PACKAGE) for m in modules))


if __name__ == "__main__":
    main()
