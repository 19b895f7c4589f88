"""On-demand reads and audited, validated writes of one parameter, for the HTTP API.

A write is refused before anything is sent unless: the bearer token is
right (compared in constant time; no token configured = no writes), the
parameter is in the drive's ``writable`` list, and the value passes the
type, range and limits of the catalog and the configuration. A value the raw
number cannot represent exactly (1.234 s on a 0.01 s parameter) is refused,
never rounded. A parameter goes by the drive's one name for it (``341`` is
``3-41`` on an FC drive, where ``p0341`` is refused) in the allow-list check,
the answer and the audit. Every attempt, refused ones included, lands in the
audit log (requests without a valid token as a count per address and minute);
a write is sent only once its row is stored (else 503), and once queued it
runs to its end and its row is completed even if the HTTP client goes away. A
drive or parameter name longer than any can be is refused before it is looked
up.

The reads are in :mod:`pkwbus.service.writes.reads`, the writes in
:mod:`pkwbus.service.http.parameter_writes`, the checks of names, token and index in
:mod:`pkwbus.service.writes.checks`; this module joins them in
:class:`ParameterService` and re-exports their public names. Everything raises
:class:`ApiError` (an HTTP status, a kind and a message), nothing else.
"""

from __future__ import annotations

from typing import Any

from pkwbus.service.audit.writer import AuditWriter
from pkwbus.service.http.parameter_writes import WriteOrder, Writes
from pkwbus.service.http.settings import DriveSettings
from pkwbus.service.runtime import Runtime
from pkwbus.service.writes.checks import (
    INCOMPLETE,
    MAX_DRIVE_NAME,
    MAX_PARAMETER_TEXT,
    ApiError,
    Caller,
    TokenCheck,
    check_names,
    clip,
)
from pkwbus.service.writes.path import WritePath
from pkwbus.service.writes.reads import MAX_READS_PER_DRIVE, Reads

__all__ = [
    "INCOMPLETE",
    "MAX_DRIVE_NAME",
    "MAX_PARAMETER_TEXT",
    "MAX_READS_PER_DRIVE",
    "ApiError",
    "Caller",
    "ParameterService",
    "WriteOrder",
    "check_names",
    "clip",
]


class ParameterService:
    """Reads and writes of one parameter at a time, as the HTTP API asks for them."""

    def __init__(self, runtime: Runtime, audit_writer: AuditWriter, token: str | None) -> None:
        self.runtime = runtime
        self.audit_writer = audit_writer
        tokens = TokenCheck(token, audit_writer.token_id(token) if token is not None else None)
        self.tokens = tokens
        self._reads = Reads(runtime)
        self._writes = Writes(runtime, audit_writer, tokens, self._reads)

    @property
    def write_path(self) -> WritePath:
        """The one write path these writes share with other callers (MQTT)."""
        return self._writes.path

    def settings(self) -> DriveSettings:
        """The drives' settings through the same reads, writes and tokens."""
        return DriveSettings(self.runtime, self.audit_writer, self.tokens, self._writes,
                             self._reads)  # fmt: skip

    async def read(self, drive: str, parameter: str, index: int | None) -> dict[str, Any]:
        return await self._reads.read(drive, parameter, index)

    async def write(
        self, drive: str, parameter: str, order: WriteOrder, caller: Caller
    ) -> dict[str, Any]:
        return await self._writes.write(drive, parameter, order, caller)

    async def refuse_malformed(
        self, drive: str, parameter: str, caller: Caller, problem: str
    ) -> bool:
        """Audit a write whose body did not validate (nothing was sent); False when the
        audit log could not store it. A caller without a valid token gets its refusal."""
        return await self._writes.refuse_malformed(drive, parameter, caller, problem)
