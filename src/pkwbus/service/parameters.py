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
"""

from __future__ import annotations

import asyncio
import hmac
from collections import Counter
from dataclasses import dataclass
from typing import Any

from pkwbus.master.jobs import JobKind, JobResult
from pkwbus.master.outcomes import Answered, audit_outcome, http_failure
from pkwbus.master.values import ParameterFormat, Value
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.params import (
    ParameterNotationError,
    ParameterRef,
    encode_text,
    parse_parameter,
)
from pkwbus.service.audit import AuditEntry
from pkwbus.service.recorder import AuditRecorder, AuditUnavailable
from pkwbus.service.runtime import DriveEntry, Runtime

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

MAX_READS_PER_DRIVE = 4  # on-demand reads of one drive waiting at once
MAX_DRIVE_NAME = 64  # the configuration's limit on names
MAX_PARAMETER_TEXT = 32  # "P65535[255]" is 11 characters: room for spaces, not for a book
INCOMPLETE = "incomplete"  # the answer's "audit" when its row could not be (fully) stored


class ApiError(Exception):
    def __init__(self, status: int, kind: str, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.kind = kind
        self.extra = extra
        self.audit_incomplete = False

    def body(self) -> dict[str, Any]:
        body: dict[str, Any] = {"error": {"kind": self.kind, "message": str(self), **self.extra}}
        if self.audit_incomplete:
            body["audit"] = INCOMPLETE
        return body


def check_names(drive: str, parameter: str) -> None:
    """Refuse, before any lookup, a name longer than a drive name or parameter can be."""
    if len(drive) > MAX_DRIVE_NAME:
        raise ApiError(404, "unknown_drive", f"no drive has a name of {len(drive)} characters")
    if len(parameter) > MAX_PARAMETER_TEXT:
        raise ApiError(
            404, "unknown_parameter", f"no parameter is written in {len(parameter)} characters"
        )


def clip(name: str, limit: int) -> str:
    """A name as the audit keeps it: at most ``limit`` characters and a mark."""
    return name if len(name) <= limit else name[:limit] + "..."


@dataclass(frozen=True)
class WriteOrder:
    value: float | int | str
    index: int | None = None
    store: pkw.Store = pkw.Store.RAM
    verify: bool = False
    dry_run: bool = False


@dataclass(frozen=True)
class Caller:
    client: str
    authorization: str | None


class ParameterService:
    def __init__(self, runtime: Runtime, recorder: AuditRecorder, token: str | None) -> None:
        self.runtime = runtime
        self.recorder = recorder
        self._token = token
        self._token_id = recorder.token_id(token) if token is not None else None
        self._running: set[asyncio.Future[dict[str, Any]]] = set()
        self._reads: Counter[str] = Counter()

    # -------------------------------------------------------------- read

    async def read(self, drive: str, parameter: str, index: int | None) -> dict[str, Any]:
        check_names(drive, parameter)
        entry, ref = self._locate(drive, parameter, index)
        fmt = entry.format_of(ref)
        ref = _fit_index(ref, fmt)
        request = self._read_request(entry, ref, fmt)
        # On-demand reads go ahead of polls and need no token: a bound per drive keeps
        # a flood of them from starving the drive's polls.
        if self._reads[entry.name] >= MAX_READS_PER_DRIVE:
            raise ApiError(
                429,
                "busy",
                f"{MAX_READS_PER_DRIVE} reads of {entry.name} are already waiting:"
                " ask again when they are answered",
            )
        self._reads[entry.name] += 1
        try:
            result = await self.runtime.submit(
                entry.name, request, JobKind.READ, fmt, parameter=ref.name, index=ref.index or 0
            )
        finally:
            self._reads[entry.name] -= 1
        self._raise_for(result)
        return self._value_body(ref, fmt, result)

    def _read_request(
        self, entry: DriveEntry, ref: ParameterRef, fmt: ParameterFormat
    ) -> pkw.PkwRequest:
        d = entry.target.dialect
        try:
            return pkw.read_parameter(d, ref.pnu, ref.index, text=fmt.is_text)
        except LocalProtocolError as exc:
            raise ApiError(404, "not_encodable", str(exc)) from None

    # ------------------------------------------------------------- write

    async def write(
        self, drive: str, parameter: str, order: WriteOrder, caller: Caller
    ) -> dict[str, Any]:
        identity = await self._identify(caller)
        audit = AuditEntry(
            client=caller.client,
            drive=clip(drive, MAX_DRIVE_NAME),
            parameter=clip(parameter, MAX_PARAMETER_TEXT),
            index=order.index or 0,
            outcome="pending",
            token_id=identity,
            store=order.store.value,
            new_value=order.value,
        )
        try:
            check_names(drive, parameter)
            entry, ref = self._locate(drive, parameter, order.index)
            audit.parameter, audit.index = ref.name, ref.index or 0
            if not entry.may_write(ref):
                raise ApiError(403, "not_writable", f"{ref.name} is not writable on {drive}")
            fmt = entry.format_of(ref)
            ref = _fit_index(ref, fmt)
            request = self._write_request(entry, ref, fmt, order)
            audit.raw_value = request.value if not request.text else None
        except ApiError as exc:
            audit.outcome = "refused" if exc.status in (401, 403) else "invalid"
            audit.detail = str(exc)
            exc.audit_incomplete = not await self.recorder.note(audit)
            raise
        telegram = entry.target.telegram(request).hex(" ")
        if order.dry_run:
            audit.outcome = "dry_run"
            stored = await self.recorder.note(audit)
            body = self._write_body(ref, fmt, order, request, telegram, audit, None)
            return body if stored else {**body, "audit": INCOMPLETE}
        # Once its row is stored the write runs to its end and the row is completed even
        # when the HTTP client goes away: the request may reach the drive regardless.
        task = asyncio.ensure_future(
            self._perform(entry, ref, fmt, order, request, telegram, audit)
        )
        self._running.add(task)
        task.add_done_callback(self._finished)
        return await asyncio.shield(task)

    def _finished(self, task: asyncio.Future[dict[str, Any]]) -> None:
        self._running.discard(task)
        if not task.cancelled():
            task.exception()  # collected: a client that left is not told, the audit row is

    async def refuse_malformed(
        self, drive: str, parameter: str, caller: Caller, problem: str
    ) -> bool:
        """Audit a write whose body did not validate (nothing was sent); False when the
        audit log could not store it. A caller without a valid token gets its refusal."""
        identity = await self._identify(caller)
        return await self.recorder.note(
            AuditEntry(
                client=caller.client,
                drive=clip(drive, MAX_DRIVE_NAME),
                parameter=clip(parameter, MAX_PARAMETER_TEXT),
                index=0,
                outcome="invalid",
                token_id=identity,
                detail=problem,
            )
        )

    async def _identify(self, caller: Caller) -> str | None:
        """The caller's token id; a refusal (counted, audited per address and minute)
        when the caller has no valid token."""
        try:
            return self._authenticate(caller)
        except ApiError as exc:
            exc.audit_incomplete = not await self.recorder.refused(caller.client, exc.kind)
            raise

    async def _perform(
        self,
        entry: DriveEntry,
        ref: ParameterRef,
        fmt: ParameterFormat,
        order: WriteOrder,
        request: pkw.PkwRequest,
        telegram: str,
        audit: AuditEntry,
    ) -> dict[str, Any]:
        # The old value is the latest the drive confirmed (polled, read, or echoed by
        # an earlier write): reading it first would cost an exchange and double the
        # write's latency. Kept at once; the line then reports the latest one just
        # before the write's answer, which a write queued behind another needs.
        old = self._latest(entry, ref)
        audit.old_value = old
        try:
            row = await self.recorder.attempt(audit)  # committed before anything is sent
        except AuditUnavailable as exc:
            raise ApiError(
                503,
                "audit_unavailable",
                f"the audit log cannot record the write ({exc}): nothing was sent",
            ) from None
        result = await self.runtime.submit(
            entry.name, request, JobKind.WRITE, fmt, parameter=ref.name, index=ref.index or 0
        )
        if result.previous is not None and result.previous.value != old:
            old = audit.old_value = result.previous.value  # stored with the outcome
        audited = audit_outcome(result.outcome, result.tally.telegrams if result.tally else 0)
        outcome, fault, detail = audited.outcome, audited.fault, audited.detail
        verified: bool | None = None
        if outcome == "ok" and order.verify:
            back = await self._try_read(entry, ref, fmt)
            if isinstance(back.outcome, Answered):
                verified = back.value == result.value if request.text else back.raw == request.value
                if not verified:
                    outcome, detail = "mismatch", f"read back {back.value!r} (raw {back.raw})"
            else:
                verified = False
                outcome, detail = "unverified", "the read-back had no answer"
        stored = await self.recorder.outcome(
            row, outcome=outcome, fault=fault, detail=detail, old_value=old
        )
        try:
            self._raise_for(result)
        except ApiError as exc:
            exc.audit_incomplete = not stored
            raise
        body = self._write_body(ref, fmt, order, request, telegram, audit, result)
        body.update(old_value=old, verified=verified)
        if not stored:
            body["audit"] = INCOMPLETE
        return body

    def _latest(self, entry: DriveEntry, ref: ParameterRef) -> Value | None:
        reading = self.runtime.snapshot.latest.get((entry.name, ref.pnu, ref.index or 0))
        return reading.value if reading is not None else None

    async def _try_read(
        self, entry: DriveEntry, ref: ParameterRef, fmt: ParameterFormat
    ) -> JobResult:
        """A read whose failure is not an error: the result, with no value when unanswered."""
        request = self._read_request(entry, ref, fmt)
        result = await self.runtime.submit(
            entry.name, request, JobKind.READ, fmt, parameter=ref.name, index=ref.index or 0
        )
        if not isinstance(result.outcome, Answered):
            return JobResult(result.outcome)
        return result

    def _write_request(
        self, entry: DriveEntry, ref: ParameterRef, fmt: ParameterFormat, order: WriteOrder
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
            request = pkw.write(d, ref.pnu, raw, width, index=ref.index, store=order.store)
            entry.target.telegram(request)
        except LocalProtocolError as exc:
            raise ApiError(422, "invalid_value", str(exc)) from None
        return request

    def _authenticate(self, caller: Caller) -> str | None:
        if self._token is None:
            raise ApiError(403, "writes_disabled", "writes are disabled: no write token is set")
        header = caller.authorization or ""
        scheme, _, given = header.partition(" ")
        if scheme.lower() != "bearer" or not given:
            raise ApiError(401, "unauthenticated", "writes need Authorization: Bearer <token>")
        if not hmac.compare_digest(given.strip().encode(), self._token.encode()):
            raise ApiError(403, "forbidden", "the token is not the write token")
        return self._token_id

    # ----------------------------------------------------------- helpers

    def _locate(
        self, drive: str, parameter: str, index: int | None
    ) -> tuple[DriveEntry, ParameterRef]:
        entry = self.runtime.drives.get(drive)
        if entry is None:
            raise ApiError(404, "unknown_drive", f"no drive named {drive!r}")
        try:
            ref = parse_parameter(parameter)
            entry.target.dialect.check_pnu(ref.pnu)
        except LocalProtocolError as exc:
            raise ApiError(404, "unknown_parameter", str(exc)) from None
        try:  # one name per drive: 341 and 0341 are 3-41 on an FC drive, p0341 is refused
            ref = entry.canonical(ref)
        except ParameterNotationError as exc:
            raise ApiError(422, "wrong_notation", str(exc)) from None
        if index is not None:
            if ref.index is not None and ref.index != index:
                raise ApiError(
                    422, "invalid_index", f"{parameter} names index {ref.index}, not {index}"
                )
            if not 0 <= index <= 255:
                raise ApiError(422, "invalid_index", f"index {index} is outside 0-255")
            ref = ParameterRef(ref.pnu, index, ref.name)
        return entry, ref

    def _raise_for(self, result: JobResult) -> None:
        failure = http_failure(result.outcome)
        if failure is not None:
            raise ApiError(failure.status, failure.kind, failure.message, **failure.extra)

    def _value_body(
        self, ref: ParameterRef, fmt: ParameterFormat, result: JobResult
    ) -> dict[str, Any]:
        return {
            "parameter": ref.name,
            "pnu": ref.pnu,
            "index": ref.index or 0,
            "raw": result.raw,
            "value": result.value,
            "unit": fmt.unit,
        }

    def _write_body(
        self,
        ref: ParameterRef,
        fmt: ParameterFormat,
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
        }


def _fit_index(ref: ParameterRef, fmt: ParameterFormat) -> ParameterRef:
    """Index 0 of a parameter the catalog does not call an array is the parameter itself;
    an index past the catalog's array length is refused before anything is sent."""
    if ref.index is None:
        return ref
    if fmt.array is None:
        return ParameterRef(ref.pnu, None, ref.name) if ref.index == 0 else ref
    if ref.index >= fmt.array:
        raise ApiError(
            422, "invalid_index", f"{ref.name} has {fmt.array} elements: index {ref.index}"
        )
    return ref
