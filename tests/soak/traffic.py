"""What the soak does to the service while it runs, and what it checks each time.

- :class:`Writer`: a write through the API every few seconds, of a value no
  other write of the run has; after a 200 the simulated drive must hold it,
  and every attempt must have its own row in the audit log (and no row may
  be there for a write nobody made).
- :class:`Scraper`: ``/metrics`` every 5 s; it must parse, and every
  ``pkwbus_parameter_value`` must be a value the line sent for that drive
  and parameter (record.py).
- :class:`Prober`: ``/healthz`` four times a second from a thread of its own;
  its longest answer is the soak's measure of the event loop's longest stall
  (the service has no gauge of its own for it), an upper bound: the answer
  also waits for the machine.
"""

from __future__ import annotations

import asyncio
import threading
import time
from dataclasses import dataclass
from typing import Any

import httpx
from prometheus_client.parser import text_string_to_metric_families

from .plan import DriveSpec, LineSpec, write_value
from .record import rounded

__all__ = ["Prober", "Problems", "Scraper", "Write", "Writer"]

# A write's answer, and the outcomes its audit row may have (not_sent: the line refused
# it before it went out, its port lost; or, 503, its drive was describing the parameter,
# back after it was away).
EXPECTED_STATUS = {200: {"ok"}, 503: {"cancelled", "not_sent"}, 504: {"timeout", "not_sent"}}
AUDIT_LIMIT = 1000  # the API's most rows per GET /api/v1/audit
MAX_PROBLEMS = 20  # of each kind, kept in full
Labels = tuple[tuple[str, str], ...]


@dataclass
class Write:
    line: str
    drive: DriveSpec
    parameter: str
    value: float
    status: int = 0


class Problems:
    def __init__(self) -> None:
        self.found: list[str] = []
        self.counts: dict[str, int] = {}

    def add(self, kind: str, text: str) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if self.counts[kind] <= MAX_PROBLEMS:
            self.found.append(text)


class Writer:
    def __init__(
        self, lines: list[LineSpec], service: httpx.AsyncClient, sims: httpx.AsyncClient,
        token: str, problems: Problems,
    ) -> None:  # fmt: skip
        self.targets = [
            (line.name, drive, parameter)
            for line in lines
            for drive in line.drives
            for parameter in drive.writable
        ]
        self.service, self.sims, self.problems = service, sims, problems
        self.auth = {"Authorization": f"Bearer {token}"}
        self.writes: list[Write] = []
        self.audited = 0  # writes whose rows were found
        self.rows_seen = 0  # the highest audit row id matched

    async def run(self, every: float, audit_every: int) -> None:
        while True:
            await self.one()
            if len(self.writes) % audit_every == 0:
                await self.check_audit()
            await asyncio.sleep(every)

    async def one(self) -> None:
        line, drive, parameter = self.targets[len(self.writes) % len(self.targets)]
        write = Write(line, drive, parameter, write_value(drive, len(self.writes) + 1))
        self.writes.append(write)
        path = f"/api/v1/drives/{drive.name}/parameters/{parameter}"
        answer = await self.service.put(path, json={"value": write.value}, headers=self.auth)
        write.status = answer.status_code
        if write.status not in EXPECTED_STATUS:
            self.problems.add("status", f"write {write}: {answer.status_code} {answer.text}")
        elif write.status == 200 and rounded(await self.held(write)) != rounded(write.value):
            self.problems.add("held", f"write {write} answered 200, the drive does not hold it")

    async def held(self, write: Write | tuple[str, DriveSpec, str]) -> float:
        line, drive, parameter = (
            (write.line, write.drive, write.parameter) if isinstance(write, Write) else write
        )
        query: dict[str, str | int] = {"line": line, "address": drive.address}
        query["parameter"] = parameter
        answer = await self.sims.get("/value", params=query)
        answer.raise_for_status()
        return float(answer.json()["value"])

    async def check_audit(self) -> None:
        """The writes since the last look each have their row, with their outcome; every
        new row is one of them."""
        answer = await self.service.get("/api/v1/audit", params={"limit": AUDIT_LIMIT},
                                        headers=self.auth)  # fmt: skip
        if answer.status_code != 200:
            self.problems.add("audit", f"GET /api/v1/audit: {answer.status_code} {answer.text}")
            return
        rows: list[dict[str, Any]] = answer.json()
        by_write: dict[tuple[str, str, float | None], dict[str, Any]] = {}
        for row in rows:
            if row["parameter"] == "reload" and not row["drive"]:
                continue  # a reload's row (the soak sends SIGHUP): not a write
            if int(row["id"]) > self.rows_seen:  # not one of the writes already matched
                by_write[row["drive"], row["parameter"], _number(row["new_value"])] = row
        for write in self.writes[self.audited :]:
            found = by_write.pop((write.drive.name, write.parameter, rounded(write.value)), None)
            if found is None and write.status == 0:  # cut off by the soak's end (below)
                # before its body was whole: audited as the unreadable request it was
                found = by_write.pop((write.drive.name, write.parameter, None), None)
            if found is None:
                if write.status != 0:  # one cut off before it was sent has no row
                    self.problems.add("unaudited", f"write {write}: no audit row")
                continue
            if write.status == 0:  # its PUT was cut off by the soak's end: no answer seen,
                pass  # so any row is right, a pending one too (the service finishes it)
            elif found["outcome"] not in EXPECTED_STATUS.get(write.status, set()):
                self.problems.add("outcome", f"write {write}: audit row says {found['outcome']}")
            self.rows_seen = max(self.rows_seen, int(found["id"]))
        for key, row in by_write.items():
            self.problems.add("invented", f"an audit row of a write nobody made: {key} {row}")
        self.audited = len(self.writes)

    async def check_held(self) -> None:
        """At the end: each parameter holds its last value answered 200, or one written
        after it whose answer did not come (which the drive may have applied)."""
        for target in self.targets:
            _, drive, parameter = target
            mine = [w for w in self.writes if (w.drive, w.parameter) == (drive, parameter)]
            last_ok = max((i for i, w in enumerate(mine) if w.status == 200), default=-1)
            allowed = {rounded(w.value) for w in mine[max(last_ok, 0) :]}
            if not mine or last_ok < 0:
                continue  # the initial value, or any write that timed out, may be there
            held = rounded(await self.held(target))
            if held not in allowed:
                self.problems.add("held", f"{drive.name} {parameter} holds {held}, not {allowed}")


def _number(value: Any) -> float | None:
    return rounded(float(value)) if isinstance(value, int | float) else None


class Scraper:
    def __init__(
        self, lines: list[LineSpec], service: httpx.AsyncClient, sims: httpx.AsyncClient,
        problems: Problems,
    ) -> None:  # fmt: skip
        self.address = {d.name: d.address for line in lines for d in line.drives}
        self.service, self.sims, self.problems = service, sims, problems
        self.longest = 0.0  # seconds, since the last take
        self.scrapes = 0
        self.checked = 0

    async def run(self, every: float) -> None:
        while True:
            await self.scrape()
            await asyncio.sleep(every)

    def take(self) -> float:
        longest, self.longest = self.longest, 0.0
        return longest

    async def scrape(self) -> dict[str, dict[Labels, float]]:
        began = time.perf_counter()
        answer = await self.service.get("/metrics")
        self.longest = max(self.longest, time.perf_counter() - began)
        self.scrapes += 1
        if answer.status_code != 200:
            self.problems.add("scrape", f"/metrics: {answer.status_code}")
            return {}
        found: dict[str, dict[Labels, float]] = {}
        try:
            for family in text_string_to_metric_families(answer.text):
                for sample in family.samples:
                    labels = tuple(sorted(sample.labels.items()))
                    found.setdefault(sample.name, {})[labels] = sample.value
        except ValueError as exc:
            self.problems.add("scrape", f"/metrics does not parse: {exc}")
            return {}
        await self.check_values(found.get("pkwbus_parameter_value", {}))
        return found

    async def check_values(self, values: dict[Labels, float]) -> None:
        items = []
        for labels, value in values.items():
            label = dict(labels)
            address = self.address[label["drive"]]
            items.append([label["line"], address, label["parameter"], label["index"], value])
        answer = await self.sims.post("/check", json=items)
        answer.raise_for_status()
        self.checked += len(items)
        for wrong in answer.json()["wrong"]:
            self.problems.add("value", f"exported {wrong}: the simulated drive never sent it")


class Prober(threading.Thread):
    """``/healthz`` every ``every`` seconds until stopped; the longest answer."""

    def __init__(self, base: str, every: float, problems: Problems) -> None:
        super().__init__(name="healthz-prober", daemon=True)
        self.base, self.every, self.problems = base, every, problems
        self.longest = 0.0
        self.longest_ever = 0.0
        self.probes = 0
        self._lock = threading.Lock()
        self._halt = threading.Event()

    def run(self) -> None:
        with httpx.Client(base_url=self.base, timeout=60) as client:
            while not self._halt.wait(self.every):
                began = time.perf_counter()
                try:
                    ok = client.get("/healthz").status_code == 200
                except httpx.HTTPError as exc:
                    ok = False
                    self.problems.add("healthz", f"/healthz: {exc!r}")
                took = time.perf_counter() - began
                with self._lock:
                    self.probes += 1
                    self.longest = max(self.longest, took)
                    self.longest_ever = max(self.longest_ever, took)
                if not ok:
                    self.problems.add("healthz", "/healthz did not answer 200")

    def take(self) -> float:
        with self._lock:
            longest, self.longest = self.longest, 0.0
        return longest

    def stop(self) -> None:
        self._halt.set()
        self.join()
