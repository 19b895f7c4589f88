"""The audit log as the HTTP API uses it: off the event loop, counted, told in one line.

The rules:

- a write's ``pending`` row is committed before its telegram is queued; when it
  cannot be stored the write is refused (:class:`AuditUnavailable`, 503) and
  nothing is sent;
- the outcome after the drive's answer is stored with a few brief retries; when
  it still cannot be, the row stays ``pending``, one log line tells the outcome,
  and the answer says ``"audit": "incomplete"``; the outcome is kept in memory
  (up to :data:`MAX_UNSAVED` rows) and stored as soon as the log records again;
- the log is *failing* from a failed store until a later store succeeds; while
  it is failing, :meth:`AuditWriter.problem` (asked by ``/readyz``) tries a
  small store at most every ``probe_interval`` seconds, so the service recovers
  once there is room again, without waiting for a write.

Every failure is counted in ``pkwbus_audit_errors_total{stage}`` and logged in
one line without a traceback; refusals of requests without a valid token are
counted in ``pkwbus_api_refusals_total{reason}`` and logged only when the log
starts failing, so a flood of them cannot flood the log.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import math
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Final, TypeVar

from pkwbus.errors import PkwbusError
from pkwbus.service.audit.log import AuditEntry, AuditError, AuditLog
from pkwbus.service.metrics.instrumentation import ApiMetrics

__all__ = ["MAX_UNSAVED", "PROBE_INTERVAL", "RETRY_DELAYS", "AuditUnavailable", "AuditWriter"]

log = logging.getLogger("pkwbus.service.recorder")  # the name its log lines have always carried

RETRY_DELAYS: Final = (0.05, 0.2, 0.5)  # seconds before each further try of an outcome
PROBE_INTERVAL: Final = 5.0  # seconds between probes while the log is failing
MAX_UNSAVED: Final = 256  # outcomes kept for a failing log; older ones stay pending

T = TypeVar("T")


class AuditUnavailable(PkwbusError):
    """The audit log cannot record a write's attempt: the write must not be sent."""


class AuditWriter:
    def __init__(
        self,
        audit: AuditLog | None,
        metrics: ApiMetrics,
        *,
        retry_delays: tuple[float, ...] = RETRY_DELAYS,
        probe_interval: float = PROBE_INTERVAL,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.audit = audit
        self.metrics = metrics
        self.retry_delays = retry_delays
        self.probe_interval = probe_interval
        self._clock = clock
        self._problem: str | None = None
        self._last_probe = -math.inf
        self._unsaved: OrderedDict[int, dict[str, Any]] = OrderedDict()
        self._thread = ThreadPoolExecutor(1, thread_name_prefix="pkwbus-audit")

    def token_id(self, token: str) -> str | None:
        return self.audit.token_id(token) if self.audit is not None else None

    async def close_interrupted(self) -> int:
        """Mark what a stopped service left pending; 0 (and failing) when it cannot."""
        if self.audit is None:
            return 0
        try:
            return await self._call(self.audit.close_interrupted)
        except AuditError as exc:
            self._failed("outcome", exc)
            log.error(
                "audit log cannot record: %s; writes are refused until it can"
                " (rows left pending by the last run stay pending)",
                exc,
            )
            return 0

    async def attempt(self, entry: AuditEntry) -> int | None:
        """Store a write's row before it is sent; :class:`AuditUnavailable` when it cannot."""
        if self.audit is None:
            return None
        try:
            row = await self._call(self.audit.record, entry)
        except AuditError as exc:
            self._failed("attempt", exc)
            log.warning(
                "write to %s %s refused: the audit log cannot record it (%s); nothing was sent",
                entry.drive,
                entry.parameter,
                exc,
            )
            raise AuditUnavailable(str(exc)) from None
        await self._succeeded()
        return row

    async def note(self, entry: AuditEntry) -> bool:
        """Store the row of an attempt that sends nothing; False when it cannot be stored."""
        if self.audit is None:
            return True
        try:
            await self._call(self.audit.record, entry)
        except AuditError as exc:
            self._failed("attempt", exc)
            log.warning(
                "audit log cannot record the %s attempt on %s %s: %s",
                entry.outcome,
                entry.drive,
                entry.parameter,
                exc,
            )
            return False
        await self._succeeded()
        return True

    async def outcome(self, row: int | None, **fields: Any) -> bool:
        """Complete a write's row, trying again briefly; False when it stays pending."""
        if self.audit is None or row is None:
            return True
        error: AuditError | None = None
        for delay in (*self.retry_delays, None):
            try:
                await self._call(self.audit.update, row, **fields)
            except AuditError as exc:
                error = exc
                if delay is not None:
                    await asyncio.sleep(delay)
                continue
            await self._succeeded()
            return True
        assert error is not None
        self._failed("outcome", error)
        what = ", ".join(f"{k} {v}" for k, v in fields.items() if v is not None)
        log.warning("audit row %d stays pending: could not store %s (%s)", row, what, error)
        self._unsaved[row] = fields
        while len(self._unsaved) > MAX_UNSAVED:
            self._unsaved.popitem(last=False)
        return False

    async def refused(self, client: str, reason: str) -> bool:
        """Count a request refused for want of a valid token; False when not stored."""
        self.metrics.refusals.labels(reason).inc()
        if self.audit is None:
            return True
        try:
            await self._call(self.audit.refused, client, reason)
        except AuditError as exc:
            if self._failed("refusals", exc):  # told once, not once per refusal
                log.error("audit log cannot record: %s; writes are refused until it can", exc)
            return False
        await self._succeeded()
        return True

    async def problem(self) -> str | None:
        """Why the log cannot record, or None. While failing, a small store is tried
        at most every ``probe_interval`` seconds: when it succeeds the log is back."""
        if self._problem is None or self.audit is None:
            return None
        now = self._clock()
        if now - self._last_probe >= self.probe_interval:
            self._last_probe = now
            try:
                await self._call(self.audit.probe)
            except AuditError as exc:
                self._problem = str(exc)
            else:
                await self._succeeded()
        return self._problem

    def save_late(self) -> None:
        """At shutdown: store the outcomes still kept, if the log records again; then
        let the audit thread end."""
        saved, _ = self._store(list(self._unsaved.items()))
        for row in saved:
            self._unsaved.pop(row, None)
        self._thread.shutdown(wait=True)

    # ----------------------------------------------------------- helpers

    async def _call(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        # SQLite syncs to disk on every commit: never on the event loop, which runs the
        # lines, and in a thread of its own, so that a flood of refusals to store does not
        # queue ahead of the ports being opened or anything else the default pool runs.
        call = functools.partial(fn, *args, **kwargs)
        return await asyncio.get_running_loop().run_in_executor(self._thread, call)

    def _failed(self, stage: str, exc: AuditError) -> bool:
        """Count a failed store and mark the log failing; True when it was not before."""
        self.metrics.audit_errors.labels(stage).inc()
        first = self._problem is None
        self._problem = str(exc)
        self._last_probe = self._clock()
        return first

    async def _succeeded(self) -> None:
        if self._problem is not None:
            self._problem = None
            log.warning("audit log records again: writes are accepted")
        if self._unsaved:
            saved, error = await self._call(self._store, list(self._unsaved.items()))
            for row in saved:
                self._unsaved.pop(row, None)
            if error is not None and self._failed("outcome", error):
                log.error("audit log cannot record: %s; writes are refused until it can", error)

    def _store(
        self, outcomes: list[tuple[int, dict[str, Any]]]
    ) -> tuple[list[int], AuditError | None]:
        """Store kept outcomes in order, until one fails; the rows stored, the failure."""
        saved: list[int] = []
        if self.audit is None:
            return saved, None
        for row, fields in outcomes:
            try:
                self.audit.update(row, **fields)
            except AuditError as exc:
                return saved, exc
            saved.append(row)
            log.info("audit row %d: its outcome is stored now", row)
        return saved, None
