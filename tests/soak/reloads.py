"""Reloads during a soak: every so often the configuration file changes a little and the
service gets SIGHUP, as an operator's edit would, while the lines lose their ports, drives
die and PROFIBUS slaves restart.

Each reload changes what must apply in place (the lines keep their ports): every line's
``events_every`` (its drives' default, so every drive is looked at and the watchers of
the drives' memory are made again) and the interval of each line's first poll (a poll
kept, its next due time). What the soak checks of the values, the writes and the audit
holds across them; here: each reload is logged as loaded, none fails.
"""

from __future__ import annotations

import asyncio
import copy
import json
import os
import signal
from pathlib import Path
from typing import Any

from .traffic import Problems

__all__ = ["Reloads"]

LOGGED_WITHIN = 60.0  # seconds for the service to log a reload's outcome


class Reloads:
    def __init__(self, config: Path, body: dict[str, Any], pid: int, log: Path,
                 problems: Problems) -> None:  # fmt: skip
        self.config = config
        self.body = body
        self.pid = pid
        self.log = log
        self.problems = problems
        self.sent = 0
        self.loaded = 0

    def _said(self) -> list[str]:
        return [s for s in self.log.read_text(errors="replace").splitlines() if "reload" in s]

    async def run(self, every: float) -> None:
        while True:
            await asyncio.sleep(every)
            await self.once()

    async def once(self) -> None:
        self.sent += 1
        varied = copy.deepcopy(self.body)
        for line in varied["lines"]:
            line["events_every"] = "12s" if self.sent % 2 else "10s"
            line["drives"][0]["poll"][0]["every"] = "1500ms" if self.sent % 2 else "1s"
        self.config.write_text(json.dumps(varied, indent=1))
        before = len(self._said())
        os.kill(self.pid, signal.SIGHUP)
        loop = asyncio.get_running_loop()
        end = loop.time() + LOGGED_WITHIN
        while len(said := self._said()) < before + 2:  # "SIGHUP: reloading", its outcome
            if loop.time() > end:
                self.problems.add("reload", f"reload {self.sent}: no outcome logged")
                return
            await asyncio.sleep(0.2)
        outcome = said[-1]
        if " error " in outcome or "cannot start" in outcome or "not applied" in outcome:
            self.problems.add("reload", f"reload {self.sent}: {outcome}")
        else:
            self.loaded += 1
