"""The soak: ``pkwbus run`` on simulated lines for an hour, measured; ``make soak``.

    python -m tests.soak.run [--minutes 60] [--lines 8] [--sample-every 60]

Starts the simulated lines (sims.py: faults on every answer, ports lost at
random, drives dead for a while, PROFIBUS slaves restarting), ``pkwbus run``
on them with a real audit database and a write token, then until the time is
up writes through the API every 3 s, scrapes ``/metrics`` every 5 s and
probes ``/healthz`` four times a second (traffic.py), and samples the
service's RSS, descriptors, threads, audit files and log (samples.py). At the
end every drive must be up again, the service must stop cleanly on SIGTERM
with no traceback in its log, and nothing may have grown without levelling
off. Prints the samples as a table; exit 0 when all held, 1 otherwise.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx

from . import procs
from .plan import LineSpec, service_config, soak_lines
from .reloads import Reloads
from .samples import Sample, judge, proc_sample, size, table, warmup
from .traffic import Prober, Problems, Scraper, Writer

__all__ = ["Settings", "Soak", "main", "soak"]

UP_AGAIN_WITHIN = 120.0  # seconds for every drive to be up once the troubles stop


@dataclass(frozen=True)
class Settings:
    minutes: float = 60.0
    lines: int = 8
    sample_every: float = 60.0
    write_every: float = 3.0
    scrape_every: float = 5.0
    drops_per_hour: float = 6.0  # per line
    restarts_per_hour: float = 12.0  # per PROFIBUS line
    deaths_per_hour: float = 4.0  # per line
    reloads_per_hour: float = 4.0  # SIGHUP with a slightly changed file (.reloads)
    seed: int = 1
    folder: Path | None = None  # default: a new temporary folder
    say: bool = True  # print each sample as it is taken


@dataclass
class Soak:
    """What a soak found."""

    settings: Settings
    folder: Path
    samples: list[Sample] = field(default_factory=list)
    problems: Problems = field(default_factory=Problems)
    events: dict[str, object] = field(default_factory=dict)
    counts: dict[str, float] = field(default_factory=dict)

    def verdict(self) -> list[str]:
        warm = warmup(self.settings.minutes * 60)
        return self.problems.found + judge(self.samples, warm)

    def report(self) -> str:
        lines = [table(self.samples), ""]
        lines += [f"{key}: {value}" for key, value in self.counts.items()]
        lines.append(f"events: {json.dumps(self.events, sort_keys=True)}")
        if self.problems.counts:
            lines.append(f"problems found, by kind: {self.problems.counts}")
        lines.append(f"folder: {self.folder}")
        return "\n".join(lines)


async def soak(settings: Settings) -> Soak:
    folder = settings.folder or Path(tempfile.mkdtemp(prefix="pkwbus-soak-"))
    folder.mkdir(parents=True, exist_ok=True)
    result = Soak(settings, folder)
    if settings.say:
        print(f"soak of {settings.minutes:g} min on {settings.lines} lines; logs in {folder}")
    lines = soak_lines(settings.lines)
    sims, started = await procs.start_sims(folder, [
        "--lines", str(settings.lines), "--seed", str(settings.seed),
        "--drops-per-hour", str(settings.drops_per_hour),
        "--restarts-per-hour", str(settings.restarts_per_hour),
        "--deaths-per-hour", str(settings.deaths_per_hour),
    ])  # fmt: skip
    try:
        async with httpx.AsyncClient(base_url=started["control"], timeout=60) as control:
            await _with_service(result, lines, started["ports"], control)
            result.events = (await control.get("/events")).json()
    finally:
        if await procs.stop(sims) != 0:
            result.problems.add("sims", f"the simulators did not end cleanly: {folder}/sims.log")
    return result


async def _with_service(
    result: Soak, lines: list[LineSpec], ports: dict[str, str], control: httpx.AsyncClient
) -> None:
    folder = result.folder
    log, config = folder / "service.log", folder / "config.yaml"
    audit = folder / "audit.sqlite"
    body = service_config(lines, ports, listen="127.0.0.1:0", audit_db=str(audit),
                          token_env=procs.TOKEN_ENV)  # fmt: skip
    config.write_text(json.dumps(body, indent=1))
    service, base = await procs.start_service(config, log)
    reloads = Reloads(config, body, service.pid, log, result.problems)
    try:
        await _drive(result, lines, service.pid, base, control, reloads)
    finally:
        code = await procs.stop(service)
    if code != 0:
        result.problems.add("exit", f"pkwbus run ended with {code} on SIGTERM")
    text = log.read_text(errors="replace")
    if "Traceback" in text:
        result.problems.add("log", f"a traceback in the service's log: {log}")
    said = text.splitlines()
    result.counts |= {
        "service log lines": len(said),
        "service log warnings": sum(" warning " in line for line in said),
        "service log errors": sum(" error " in line for line in said),
        "ports lost, as the service logged them": sum(": lost " in line for line in said),
    }


async def _drive(
    result: Soak,
    lines: list[LineSpec],
    pid: int,
    base: str,
    control: httpx.AsyncClient,
    reloads: Reloads,
) -> None:
    """Writes, scrapes and probes for the soak's time, sampling the service as it goes;
    then calm, and the checks at the end."""
    settings, problems = result.settings, result.problems
    audit, log = result.folder / "audit.sqlite", result.folder / "service.log"
    prober = Prober(base, 0.25, problems)
    prober.start()
    async with httpx.AsyncClient(base_url=base, timeout=60) as client:
        writer = Writer(lines, client, control, procs.TOKEN, problems)
        scraper = Scraper(lines, client, control, problems)
        tasks = [
            asyncio.create_task(writer.run(settings.write_every, audit_every=20)),
            asyncio.create_task(scraper.run(settings.scrape_every)),
        ]
        if settings.reloads_per_hour > 0:
            tasks.append(asyncio.create_task(reloads.run(3600 / settings.reloads_per_hour)))
        try:
            loop = asyncio.get_running_loop()
            began = loop.time()
            end = began + settings.minutes * 60
            while (now := loop.time()) < end:
                await _until(tasks, min(settings.sample_every, end - now))
                rss, fds, threads = proc_sample(pid)
                sample = Sample(
                    loop.time() - began, rss, fds, threads, size(audit),
                    size(Path(f"{audit}-wal")), size(log), len(writer.writes),
                    prober.take(), scraper.take(),
                )  # fmt: skip
                result.samples.append(sample)
                if settings.say:
                    print(table(result.samples).splitlines()[-1], flush=True)
        finally:
            for task in tasks:
                task.cancel()
            ended = await asyncio.gather(*tasks, return_exceptions=True)
            prober.stop()
        for outcome in ended:
            if isinstance(outcome, Exception):
                problems.add("soak", f"the soak's own task failed: {outcome!r}")
        calmed = (await control.post("/calm")).json()
        if calmed["failed"]:
            problems.add("sims", f"the simulated lines failed: {calmed['failed']}")
        await writer.check_audit()
        await writer.check_held()
        await _all_up_again(scraper, problems)
        result.counts = {
            "writes": len(writer.writes),
            "writes answered 200": sum(w.status == 200 for w in writer.writes),
            "scrapes": scraper.scrapes,
            "values checked": scraper.checked,
            "healthz probes": prober.probes,
            "reloads sent": reloads.sent,
            "reloads loaded": reloads.loaded,
            "longest healthz answer (s)": round(prober.longest_ever, 3),
        }


async def _until(tasks: list[asyncio.Task[None]], seconds: float) -> None:
    """Wait ``seconds``; a task of the soak that ends meanwhile ends the soak (re-raised)."""
    done, _ = await asyncio.wait(tasks, timeout=seconds, return_when=asyncio.FIRST_COMPLETED)
    for task in done:
        task.result()


async def _all_up_again(scraper: Scraper, problems: Problems) -> None:
    """Every drive up and every line's port open, within a while of the calm."""
    loop = asyncio.get_running_loop()
    end = loop.time() + UP_AGAIN_WITHIN
    while True:
        found = await scraper.scrape()
        down = [dict(k) for name in ("pkwbus_drive_up", "pkwbus_line_up")
                for k, v in found.get(name, {}).items() if v != 1]  # fmt: skip
        if found and not down:
            return
        if loop.time() > end:
            problems.add("down", f"still down {UP_AGAIN_WITHIN:g} s after the end: {down}")
            return
        await asyncio.sleep(1.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tests.soak.run",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--minutes", type=float, default=float(os.environ.get("SOAK_MINUTES", 60)))
    parser.add_argument("--lines", type=int, default=int(os.environ.get("SOAK_LINES", 8)))
    parser.add_argument("--sample-every", type=float, default=60.0, metavar="SECONDS")
    parser.add_argument("--drops-per-hour", type=float, default=6.0, help="per line")
    parser.add_argument("--reloads-per-hour", type=float, default=4.0, help="SIGHUPs")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--folder", type=Path, help="keep the logs, config and audit here")
    args = parser.parse_args(argv)
    if not (args.minutes > 0 and 1 <= args.lines <= 30 and args.sample_every > 0):
        parser.error("--minutes and --sample-every must be positive, --lines 1-30")
    settings = Settings(
        minutes=args.minutes,
        lines=args.lines,
        sample_every=args.sample_every,
        drops_per_hour=args.drops_per_hour,
        reloads_per_hour=args.reloads_per_hour,
        seed=args.seed,
        folder=args.folder,
    )
    began = time.monotonic()
    result = asyncio.run(soak(settings))
    print(result.report())
    problems = result.verdict()
    for problem in problems:
        print(f"FAIL: {problem}")
    print(
        f"soak of {settings.minutes:g} min on {settings.lines} lines:"
        f" {'FAILED' if problems else 'passed'} ({time.monotonic() - began:.0f} s)"
    )
    return 1 if problems else 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())
