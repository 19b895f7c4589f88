"""The one write path of one parameter, for every caller: the HTTP API, MQTT, a restore.

A write is refused before anything is sent unless the parameter is in the drive's
``writable`` list and the value passes the type, range and limits of the catalog and
the configuration (a value the raw number cannot represent exactly is refused, never
rounded). Every attempt, refused ones included, lands in the audit log with its caller
(an HTTP client's address and token id, ``mqtt:{user}``); a write is sent only once
its row is stored, and once queued it runs to its end and its row is completed even if
the caller goes away. With ``verify`` the value is read back and compared. A write goes
only to the drive it was checked against: a reload that removed the drive or changed
its entry while the row was being stored refuses it, nothing sent (404 unknown_drive,
503 cancelled), its row completed.

Who may write at all (the HTTP API's token) is the caller's to check first: this path
starts from a caller already identified.

Raises :class:`~pkwbus.service.writes.checks.ApiError` (with the audited outcome and
row id when they are known): 403 for a parameter that is not writable, 422 for a value
that does not fit, 503 when the audit log cannot store the row (nothing sent), those of
the checks (:mod:`pkwbus.service.writes.checks`) and of the job's outcome.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.master.planning.carrier import Preview
from pkwbus.master.planning.jobs import JobKind, JobResult
from pkwbus.master.planning.outcomes import Answered, LineFailed, Mismatch, TimedOut
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.values import ParameterRef, encode_text
from pkwbus.service.audit.log import AuditEntry
from pkwbus.service.audit.writer import AuditUnavailable, AuditWriter
from pkwbus.service.runtime import DriveEntry, Runtime
from pkwbus.service.writes.checks import (
    INCOMPLETE,
    MAX_DRIVE_NAME,
    MAX_PARAMETER_TEXT,
    ApiError,
    Caller,
    check_names,
    clip,
    described_format,
    fit_index,
    locate,
    malformed,
    not_here,
    raise_for,
)
from pkwbus.service.writes.outcomes import audit_outcome
from pkwbus.service.writes.reads import Reads

__all__ = ["WriteDone", "WriteOrder", "WritePath", "refusal_outcome"]


@dataclass(frozen=True)
class WriteOrder:
    value: float | int | str
    index: int | None = None
    store: pkw.Store = pkw.Store.RAM
    verify: bool = False
    dry_run: bool = False
    # A restore's write: any parameter of the backup, the ``writable`` list aside.
    restoring: bool = False


@dataclass(frozen=True)
class WriteDone:
    """A write that ran: the HTTP API's answer and the outcome its audit row holds
    (``ok``, ``dry_run``, or after a read-back ``mismatch`` or ``unverified``)."""

    body: dict[str, Any]
    outcome: str


def refusal_outcome(exc: ApiError) -> str:
    """The audit outcome of a write refused before anything was sent."""
    if exc.kind in ("not_described", "in_maintenance", "not_master"):  # not sent, for now
        return "not_sent"
    return "refused" if exc.status in (401, 403) else "invalid"


class WritePath:
    """The writes of a runtime, each audited through ``audit_writer``."""

    def __init__(self, runtime: Runtime, audit_writer: AuditWriter, reads: Reads) -> None:
        self.runtime = runtime
        self.audit_writer = audit_writer
        self._reads = reads
        self._running: set[asyncio.Future[WriteDone]] = set()

    async def write(
        self,
        drive: str,
        parameter: str,
        order: WriteOrder,
        client: str,
        token_id: str | None = None,
    ) -> WriteDone:
        """Write ``parameter`` of ``drive`` for ``client`` (whose token is ``token_id``)."""
        audit = AuditEntry(
            client=client,
            drive=clip(drive, MAX_DRIVE_NAME),
            parameter=clip(parameter, MAX_PARAMETER_TEXT),
            index=order.index or 0,
            outcome="pending",
            token_id=token_id,
            store=order.store.value,
            new_value=order.value,
        )
        try:
            check_names(drive, parameter)
            entry, ref = locate(self.runtime, drive, parameter, order.index)
            audit.parameter, audit.index = ref.name, ref.index or 0
            if not order.restoring and not entry.may_write(ref):
                raise ApiError(403, "not_writable", f"{ref.name} is not writable on {drive}")
            fmt = described_format(self.runtime, entry, ref)
            ref = fit_index(ref, fmt)
            request = self._write_request(entry, ref, fmt, order)
            preview = self._preview(entry, ref, fmt, request)
            audit.raw_value = request.value if not request.text else None
        except ApiError as exc:
            audit.outcome = exc.outcome = refusal_outcome(exc)
            audit.detail = str(exc)
            exc.audit_incomplete = not await self.audit_writer.note(audit)
            exc.audit_id = audit.id
            raise
        telegram = preview.telegram.hex(" ")
        if order.dry_run:
            audit.outcome = "dry_run"
            audit.old_value = old = self._latest(entry, ref)  # what it would change from
            stored = await self.audit_writer.note(audit)
            body = self._write_body(entry, ref, fmt, order, request, telegram, audit, None)
            body["old_value"] = old
            if preview.note:
                body["telegram_note"] = preview.note
            return WriteDone(body if stored else {**body, "audit": INCOMPLETE}, "dry_run")
        # Once its row is stored the write runs to its end and the row is completed even
        # when the caller goes away: the request may reach the drive regardless.
        task = asyncio.ensure_future(
            self._perform(entry, ref, fmt, order, request, telegram, audit)
        )
        self._running.add(task)
        task.add_done_callback(self._finished)
        return await asyncio.shield(task)

    def _changed(self, entry: DriveEntry) -> ApiError | None:
        """Why a write checked against ``entry`` does not go out now that its row is stored:
        a reload removed its drive or made it a new entry meanwhile (another address,
        catalog, ``writable`` list or limits, maybe); None: it goes, to the drive checked.
        Queued at once after this, its job ends if a reload changes the drive later."""
        now = self.runtime.drives.get(entry.name)
        if now is entry:
            return None
        if now is None:  # removed, or (hot standby) its line taken by another instance
            return not_here(
                self.runtime, entry.name,
                f"no drive named {entry.name!r} now: a reload removed it while the write was"
                " being recorded; nothing was sent",
            )  # fmt: skip
        changed = ApiError(
            503, "cancelled",
            f"a reload changed {entry.name}'s configuration while the write was being"
            " recorded: nothing was sent; send it again if it still applies",
        )  # fmt: skip
        changed.outcome = "cancelled"
        return changed

    def _finished(self, task: asyncio.Future[WriteDone]) -> None:
        self._running.discard(task)
        if not task.cancelled():
            task.exception()  # collected: a caller that left is not told, the audit row is

    async def refuse_malformed(
        self, drive: str, parameter: str, client: str, token_id: str | None, problem: str
    ) -> bool:
        """Audit a write whose request did not validate (nothing was sent); False when the
        audit log could not store it."""
        row = malformed(Caller(client, None), token_id, drive, parameter, problem)
        return await self.audit_writer.note(row)

    async def refuse(
        self, drive: str, parameter: str, index: int | None, client: str, exc: ApiError
    ) -> bool:
        """Audit a write its caller refused before the path saw it (a retained or expired
        MQTT set), as ``exc.outcome`` (else as the path refuses): nothing was sent. False
        when the audit log could not store it; ``exc.audit_id`` is its row."""
        exc.outcome = exc.outcome or refusal_outcome(exc)
        audit = AuditEntry(
            client=client,
            drive=clip(drive, MAX_DRIVE_NAME),
            parameter=clip(parameter, MAX_PARAMETER_TEXT),
            index=index or 0,
            outcome=exc.outcome,
            detail=str(exc),
        )
        stored = await self.audit_writer.note(audit)
        exc.audit_id = audit.id
        return stored

    async def _perform(
        self,
        entry: DriveEntry,
        ref: ParameterRef,
        fmt: ParameterDescription,
        order: WriteOrder,
        request: pkw.PkwRequest,
        telegram: str,
        audit: AuditEntry,
    ) -> WriteDone:
        # The old value is the latest the drive confirmed (polled, read, or echoed by
        # an earlier write): reading it first would cost an exchange and double the
        # write's latency. Kept at once; the line then reports the latest one just
        # before the write's answer, which a write queued behind another needs.
        old = self._latest(entry, ref)
        audit.old_value = old
        try:
            row = await self.audit_writer.attempt(audit)  # committed before anything is sent
        except AuditUnavailable as exc:
            refusal = ApiError(
                503,
                "audit_unavailable",
                f"the audit log cannot record the write ({exc}): nothing was sent",
            )
            refusal.outcome = "not_sent"
            raise refusal from None
        if (changed := self._changed(entry)) is not None:  # checked, then a reload came
            changed.audit_id = audit.id
            changed.audit_incomplete = not await self.audit_writer.outcome(
                row, outcome=changed.outcome, detail=str(changed)
            )
            raise changed
        result = await self.runtime.submit(
            entry.name, request, JobKind.WRITE, fmt, parameter=ref.name, index=ref.index or 0
        )
        await self._tell_settings(entry, ref, request, result, order)
        if result.previous is not None and result.previous.value != old:
            old = audit.old_value = result.previous.value  # stored with the outcome
        audited = audit_outcome(result.outcome, result.tally.telegrams if result.tally else 0)
        outcome, fault, detail = audited.outcome, audited.fault, audited.detail
        verified: bool | None = None
        read_back = None  # the value read back, where it matched
        if outcome == "ok" and order.verify:
            back = await self._reads.try_read(entry, ref, fmt)
            if isinstance(back.outcome, Answered):
                verified = back.value == result.value if request.text else back.raw == request.value
                if not verified:
                    outcome, detail = "mismatch", f"read back {back.value!r} (raw {back.raw})"
                else:
                    read_back = back.value
            else:
                verified = False
                outcome, detail = "unverified", "the read-back had no answer"
        stored = await self.audit_writer.outcome(
            row, outcome=outcome, fault=fault, detail=detail, old_value=old
        )
        try:
            raise_for(result)
        except ApiError as exc:
            exc.audit_incomplete = not stored
            exc.outcome, exc.audit_id = outcome, audit.id
            raise
        body = self._write_body(entry, ref, fmt, order, request, telegram, audit, result)
        body.update(old_value=old, verified=verified)
        if body["value"] is None and read_back is not None:  # an answer without the value
            body["value"] = read_back  # (data record 47): the value the read-back confirmed
        if not stored:
            body["audit"] = INCOMPLETE
        return WriteDone(body, outcome)

    async def _tell_settings(
        self,
        entry: DriveEntry,
        ref: ParameterRef,
        request: pkw.PkwRequest,
        result: JobResult,
        order: WriteOrder,
    ) -> None:
        """An audited write is the setting's baseline now, before any later sweep reads it:
        the value the drive answered; one it acknowledged with another number, that one;
        one whose answer got lost, the value written if a sweep finds it there."""
        settings = self.runtime.settings
        if settings is None or request.text:
            return
        index, outcome = ref.index or 0, result.outcome
        if isinstance(outcome, Answered):
            value = result.value if result.value is not None else order.value
            await settings.written(entry.name, ref.pnu, index, request.value, value)
        elif isinstance(outcome, Mismatch):
            await settings.written(entry.name, ref.pnu, index, outcome.answered, None)
        elif isinstance(outcome, TimedOut | LineFailed):
            await settings.written(entry.name, ref.pnu, index, request.value, order.value,
                                   answered=False)  # fmt: skip

    def _latest(self, entry: DriveEntry, ref: ParameterRef) -> Value | None:
        reading = self.runtime.snapshot.latest.get((entry.name, ref.pnu, ref.index or 0))
        return reading.value if reading is not None else None

    def _write_request(
        self, entry: DriveEntry, ref: ParameterRef, fmt: ParameterDescription, order: WriteOrder
    ) -> pkw.PkwRequest:
        d = entry.target.dialect
        try:
            if fmt.is_text:
                if not isinstance(order.value, str):
                    raise LocalProtocolError(f"{ref.name} is a text parameter: send a string")
                return pkw.write_text(d, ref.pnu, encode_text(order.value), ref.index or 0)
            if isinstance(order.value, bool):
                raise LocalProtocolError(f"{ref.name} takes a number, not true or false")
            if isinstance(order.value, str):
                raise LocalProtocolError(f"{ref.name} takes a number, not a string")
            raw, width = fmt.encode(order.value, str(ref))
            return pkw.write(d, ref.pnu, raw, width, index=ref.index, store=order.store)
        except LocalProtocolError as exc:
            raise ApiError(422, "invalid_value", str(exc)) from None

    def _preview(
        self, entry: DriveEntry, ref: ParameterRef, fmt: ParameterDescription,
        request: pkw.PkwRequest,
    ) -> Preview:  # fmt: skip
        """The request as the drive's carrier would send it now: its check, and the bytes
        a dry run shows."""
        try:
            return self.runtime.preview(entry.name, request, fmt.vtype)
        except LocalProtocolError as exc:
            raise ApiError(422, "invalid_value", str(exc)) from None

    def _write_body(
        self,
        entry: DriveEntry,
        ref: ParameterRef,
        fmt: ParameterDescription,
        order: WriteOrder,
        request: pkw.PkwRequest,
        telegram: str,
        audit: AuditEntry,
        result: JobResult | None,
    ) -> dict[str, Any]:
        return {
            "parameter": ref.name,
            "pnu": ref.pnu,
            "index": ref.index or 0,
            "value": result.value if result is not None else order.value,
            "raw": request.value if not request.text else None,
            "unit": fmt.unit,
            "store": order.store.value,
            "dry_run": order.dry_run,
            "telegram": telegram,
            "audit_id": audit.id,
            "access": entry.access,
        }
