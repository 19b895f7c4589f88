"""A drive put in maintenance from the API, and taken out of it, audited.

``PUT /api/v1/drives/{drive}/maintenance`` with the write token: ``{"on": true,
"reason": "bearing change"}`` and nothing goes out to the drive (its line's
planner gives it nothing, a DP slave is left out of the cycle) until ``{"on":
false}``, which brings it back as a drive that came back. Each switch is a row
of the audit log (parameter ``maintenance``, the new state as its value, the
reason as its detail), stored before the switch: an audit log that cannot
store it leaves the drive as it was (503); a drive a reload removed meanwhile
is 404, its row completed. What the API switched on is kept
(``Runtime.api_maintenance``): a reload keeps it, whatever its reason, on the
line that runs the drive after it (README "A drive in maintenance").
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from pkwbus.master.snapshot import Maintained
from pkwbus.service.audit.log import AuditEntry
from pkwbus.service.audit.writer import AuditWriter
from pkwbus.service.runtime import LineTask, Runtime
from pkwbus.service.writes.checks import (
    INCOMPLETE,
    MAX_DRIVE_NAME,
    Caller,
    TokenCheck,
    attempted,
    clip,
    identified,
    malformed,
    not_here,
)

__all__ = ["MAINTENANCE", "Maintenance"]

MAINTENANCE = "maintenance"  # the audit row's parameter


class Maintenance:
    """Switches drives in and out of maintenance for the API, each switch audited."""

    def __init__(self, runtime: Runtime, audit_writer: AuditWriter, tokens: TokenCheck) -> None:
        self.runtime = runtime
        self.audit_writer = audit_writer
        self._tokens = tokens

    async def _identify(self, caller: Caller) -> str | None:
        return await identified(self._tokens, self.audit_writer, caller)

    async def refuse_malformed(self, drive: str, caller: Caller, problem: str) -> bool:
        """Audit a switch whose body did not validate (nothing changed); False when the
        audit log could not store it. A caller without a valid token gets its refusal."""
        identity = await self._identify(caller)
        return await self.audit_writer.note(
            malformed(caller, identity, drive, MAINTENANCE, problem)
        )

    async def switch(self, drive: str, on: bool, reason: str, caller: Caller) -> dict[str, Any]:
        identity = await self._identify(caller)
        audit = AuditEntry(
            client=caller.client, drive=clip(drive, MAX_DRIVE_NAME), parameter=MAINTENANCE,
            index=0, outcome="pending", token_id=identity, new_value=on, detail=reason or None,
        )  # fmt: skip
        if self._line_of(drive) is None:
            refusal = not_here(self.runtime, drive, f"no drive named {drive!r}")
            audit.outcome = refusal.outcome or "invalid"  # not_here gives one
            refusal.audit_incomplete = not await self.audit_writer.note(audit)
            raise refusal
        row = await attempted(self.audit_writer, audit, "the drive stays as it was")
        # The drive as it is now: a reload may have removed it while the row was stored.
        runner = self._line_of(drive)
        if runner is None:  # removed, or (hot standby) its line lost meanwhile
            refusal = not_here(
                self.runtime,
                drive,
                f"no drive named {drive!r} (a reload removed it): nothing changed",
            )
            stored = await asyncio.shield(
                self.audit_writer.outcome(row, outcome=refusal.outcome, detail=str(refusal))
            )
            refusal.audit_incomplete = not stored
            raise refusal
        held = self._switch(drive, on, reason, runner)
        # Done: its row is completed even when the client goes away meanwhile.
        stored = await asyncio.shield(self.audit_writer.outcome(row, outcome="ok"))
        body: dict[str, Any] = {
            "drive": drive,
            "on": held is not None,
            "reason": held.reason if held is not None else "",
            "since": held.since if held is not None else None,
        }
        if not stored:
            body["audit"] = INCOMPLETE
        return body

    def _line_of(self, drive: str) -> LineTask | None:
        """The runner of ``drive``'s line in the running load (None: no such drive here)."""
        entry = self.runtime.drives.get(drive)
        return self.runtime.runners.get(entry.line) if entry is not None else None

    def _switch(self, drive: str, on: bool, reason: str, runner: LineTask) -> Maintained | None:
        """Switch ``drive`` as the API asks, kept as the API's: a reload keeps it on whichever
        line runs the drive then, also a line it opens again now; on its running line at
        once. A drive in maintenance already stays so as it is shown (its reason, since).
        The maintenance now (None: none)."""
        runtime, held = self.runtime, None
        if on:
            shown = runtime.snapshot.maintenance.get(drive)
            held = runtime.hold_maintenance(drive, shown or Maintained(reason, time.time()))
        else:
            runtime.end_maintenance(drive)
        runtime.show_maintenance(runner, drive)
        return held
