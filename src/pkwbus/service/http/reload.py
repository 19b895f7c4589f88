"""``POST /api/v1/reload`` (write token) and ``SIGHUP``: the configuration file read again
and what changed applied (:mod:`pkwbus.service.assembly.reload`), each reload audited.

The audit row (parameter ``reload``, no drive) is stored before anything changes
and completed with the outcome: ``ok`` with what changed and what a restart must
apply, or ``invalid`` with the file's problems (nothing changed). When the audit
log cannot store it, nothing is reloaded (503, or a log line for a signal).
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any, Protocol

from pkwbus.errors import PkwbusError
from pkwbus.service.audit.rows import AuditEntry
from pkwbus.service.audit.writer import AuditWriter
from pkwbus.service.writes.checks import (
    INCOMPLETE,
    ApiError,
    Caller,
    TokenCheck,
    attempted,
    identified,
)

__all__ = ["RELOAD", "ReloadRefused", "Reloaded", "Reloading", "Reloads"]

log = logging.getLogger("pkwbus.service.reload")

RELOAD = "reload"  # the audit row's parameter
MAX_PROBLEMS = 50  # of a broken file, in one answer (the log has them all)


class ReloadRefused(PkwbusError):
    """No reload now: the service is stopping."""


class Reloaded(Protocol):
    @property
    def loaded(self) -> bool: ...
    @property
    def outcome(self) -> str: ...
    @property
    def problems(self) -> list[str]: ...
    @property
    def changes(self) -> list[str]: ...
    @property
    def refused(self) -> list[str]: ...
    def summary(self) -> str: ...


class Reloading(Protocol):
    async def reload(self) -> Reloaded: ...
    async def close(self) -> None: ...


class Reloads:
    """Reloads for the API and the signal, audited."""

    def __init__(self, reloader: Reloading, audit_writer: AuditWriter, tokens: TokenCheck) -> None:
        self.reloader = reloader
        self.audit_writer = audit_writer
        self.tokens = tokens

    async def close(self) -> None:
        """No more reloads (the service stops); one under way finishes first."""
        await self.reloader.close()

    async def by_signal(self, name: str = "SIGHUP") -> None:
        """A reload a signal asked for: its outcome in the log and the audit log."""
        entry = AuditEntry(client=name, drive="", parameter=RELOAD, index=0, outcome="pending")
        try:
            await self._run(entry)
        except (ApiError, ReloadRefused) as exc:
            log.error("reload (%s) not done: %s", name, exc)
        except Exception as exc:  # a defect: said in one line, the service goes on
            log.error("reload (%s) failed: %r", name, exc)

    async def by_api(self, caller: Caller) -> dict[str, Any]:
        """A reload the API asked for (write token): what changed, or 422 with the file's
        problems (nothing changed)."""
        identity = await identified(self.tokens, self.audit_writer, caller)
        entry = AuditEntry(
            client=caller.client, drive="", parameter=RELOAD, index=0, outcome="pending",
            token_id=identity,
        )  # fmt: skip
        outcome, stored = await self._run(entry)
        if not outcome.loaded:
            refusal = ApiError(
                422, "invalid_configuration",
                "the configuration file has problems: the running configuration stays",
                problems=outcome.problems[:MAX_PROBLEMS],
            )  # fmt: skip
            refusal.audit_incomplete = not stored
            raise refusal
        body: dict[str, Any] = {
            "loaded": True,
            "changes": outcome.changes,
            "refused": outcome.refused,
            "problems": outcome.problems,  # lines that could not start
        }
        if not stored:
            body["audit"] = INCOMPLETE
        return body

    async def _run(self, entry: AuditEntry) -> tuple[Reloaded, bool]:
        row = await attempted(self.audit_writer, entry, "nothing was reloaded")
        # Once begun, a reload is finished and recorded even when the client goes away.
        try:
            outcome = await asyncio.shield(self.reloader.reload())
        except ReloadRefused as exc:
            await asyncio.shield(self.audit_writer.outcome(row, outcome="refused", detail=str(exc)))
            raise ApiError(503, "stopping", f"not reloaded: {exc}") from None
        stored = await asyncio.shield(
            self.audit_writer.outcome(row, outcome=outcome.outcome, detail=outcome.summary())
        )
        return outcome, stored
