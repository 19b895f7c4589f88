"""Audited, validated writes of one parameter for the HTTP API.

The HTTP API's part is the write token: a caller without it is refused (401/403,
counted and audited per address and minute) before anything else; the rest is the one
write path every caller shares (:mod:`pkwbus.service.writes.path`: ``writable``,
limits, the audit row before the wire, the job, the read-back), whose rules hold here
unchanged: a write is sent only once its row is stored, and once queued it runs to its
end and its row is completed even if the HTTP client goes away.

Raises :class:`~pkwbus.service.writes.checks.ApiError`: 401/403 for the token, and
those of the write path.
"""

from __future__ import annotations

from typing import Any

from pkwbus.service.audit.writer import AuditWriter
from pkwbus.service.runtime import Runtime
from pkwbus.service.writes.checks import Caller, TokenCheck, identified
from pkwbus.service.writes.path import WriteOrder, WritePath
from pkwbus.service.writes.reads import Reads

__all__ = ["WriteOrder", "Writes"]


class Writes:
    """The writes of a runtime by holders of the write token, each audited through
    ``audit_writer``; :attr:`path` is the write path they share with other callers."""

    def __init__(
        self, runtime: Runtime, audit_writer: AuditWriter, tokens: TokenCheck, reads: Reads
    ) -> None:
        self.runtime = runtime
        self.audit_writer = audit_writer
        self._tokens = tokens
        self.path = WritePath(runtime, audit_writer, reads)

    async def write(
        self, drive: str, parameter: str, order: WriteOrder, caller: Caller
    ) -> dict[str, Any]:
        identity = await self._identify(caller)
        done = await self.path.write(drive, parameter, order, caller.client, identity)
        return done.body

    async def refuse_malformed(
        self, drive: str, parameter: str, caller: Caller, problem: str
    ) -> bool:
        """Audit a write whose body did not validate (nothing was sent); False when the
        audit log could not store it. A caller without a valid token gets its refusal."""
        identity = await self._identify(caller)
        return await self.path.refuse_malformed(drive, parameter, caller.client, identity, problem)

    async def _identify(self, caller: Caller) -> str | None:
        return await identified(self._tokens, self.audit_writer, caller)
