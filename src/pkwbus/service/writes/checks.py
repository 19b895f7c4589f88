"""What the parameter API checks before anything is sent: names, the caller's token, the index.

:class:`ApiError` is the one error of the parameter API, over HTTP and MQTT alike: an
HTTP status, a kind and a message (and, for a write, its audited outcome and row).
The checks here raise it: :func:`check_names` (404, a name longer than any can be),
:class:`TokenCheck` (the HTTP API's: 403 when writes are disabled or the token is
wrong, 401 without a bearer token; compared in constant time),
:func:`locate` (404 unknown drive or parameter, 422 wrong notation or index, 409 a
drive whose line another instance masters: :func:`mastered_elsewhere`),
:func:`fit_index` (422 index past the array) and :func:`raise_for` (the
failure of a job's outcome).
"""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from typing import Any, NoReturn

from pkwbus.catalog.description import ParameterDescription
from pkwbus.errors import PkwbusError
from pkwbus.master.planning.jobs import JobResult
from pkwbus.master.snapshot import LiveSlave
from pkwbus.master.wires.profibus.refusal import CONFIGURATION, why_not_exchanging
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus.dp.slave_model import SlaveState
from pkwbus.protocol.values import ParameterNotationError, ParameterRef, parse_parameter
from pkwbus.service.audit.log import AuditEntry
from pkwbus.service.audit.writer import AuditUnavailable, AuditWriter
from pkwbus.service.runtime import DriveEntry, Masters, Runtime
from pkwbus.service.writes.outcomes import http_failure

__all__ = [
    "INCOMPLETE",
    "MAX_DRIVE_NAME",
    "MAX_PARAMETER_TEXT",
    "ApiError",
    "Caller",
    "TokenCheck",
    "attempted",
    "check_names",
    "clip",
    "described_format",
    "fit_index",
    "identified",
    "line_mastered_elsewhere",
    "locate",
    "malformed",
    "mastered_elsewhere",
    "not_exchanging",
    "not_here",
    "raise_for",
]

MAX_DRIVE_NAME = 64  # the configuration's limit on names
MAX_PARAMETER_TEXT = 32  # "P65535[255]" is 11 characters: room for spaces, not for a book
INCOMPLETE = "incomplete"  # the answer's "audit" when its row could not be (fully) stored


class ApiError(PkwbusError):
    def __init__(self, status: int, kind: str, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.kind = kind
        self.extra = extra
        self.audit_incomplete = False
        # A write's audit outcome (``refused``, ``timeout``, ...) and row id, once known:
        # what an MQTT result says; never part of the HTTP body.
        self.outcome: str | None = None
        self.audit_id: int | None = None

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


def described_format(
    runtime: Runtime, entry: DriveEntry, ref: ParameterRef
) -> ParameterDescription:
    """What ``ref`` is on the drive; 503 while the drive has not described it yet (a value
    written or read now would be scaled as the catalog says, maybe not as the drive does).
    Where nothing else types it, the type the drive named in its own answers."""
    snapshot = runtime.snapshot
    decoding = snapshot.decoding.get(entry.name)
    if decoding is not None and ref.pnu in decoding.pending:
        state = snapshot.drives.get(entry.name)
        slave = snapshot.slaves.get(entry.name)
        if state is not None and not state.up and slave is not None:  # a DP slave
            why = (
                f"{entry.name} is down: {not_exchanging(entry, slave)}; it describes"
                f" {ref.name} once it is in data exchange"
            )
        elif state is not None and not state.up:  # a few seconds would not do: say why
            why = f"{entry.name} is down: it describes {ref.name} once it answers again"
        else:
            why = f"{entry.name} has not described {ref.name} yet: try again in a few seconds"
        raise ApiError(503, "not_described", why)
    return runtime.format_of(entry.name, ref)


def not_exchanging(entry: DriveEntry, slave: LiveSlave) -> str:
    """Why DP slave ``entry`` is not in data exchange: its state, and the cause its
    diagnosis gives where it gives one."""
    said = f"not in data exchange ({slave.state.value})"
    locked = slave.state is SlaveState.LOCKED
    cause = why_not_exchanging(
        entry.target.address, locked, slave.owner, slave.flags, slave.ident, None, CONFIGURATION
    )
    return f"{said}: {cause}" if cause is not None else said


def clip(name: str, limit: int) -> str:
    """A name as the audit keeps it: at most ``limit`` characters and a mark."""
    return name if len(name) <= limit else name[:limit] + "..."


@dataclass(frozen=True)
class Caller:
    client: str
    authorization: str | None


class TokenCheck:
    """The write token (None: no writes) and the id the audit knows it by."""

    def __init__(self, token: str | None, token_id: str | None) -> None:
        self._token = token
        self._token_id = token_id

    def set(self, token: str | None, token_id: str | None) -> None:
        """Another write token from now on (a reload)."""
        self._token, self._token_id = token, token_id

    def identify(self, caller: Caller) -> str | None:
        """The token id of a caller with the write token; an :class:`ApiError` otherwise."""
        if self._token is None:
            raise ApiError(403, "writes_disabled", "writes are disabled: no write token is set")
        header = caller.authorization or ""
        scheme, _, given = header.partition(" ")
        if scheme.lower() != "bearer" or not given:
            raise ApiError(401, "unauthenticated", "writes need Authorization: Bearer <token>")
        if not hmac.compare_digest(given.strip().encode(), self._token.encode()):
            raise ApiError(403, "forbidden", "the token is not the write token")
        return self._token_id


def malformed(
    caller: Caller, identity: str | None, drive: str, parameter: str, problem: str
) -> AuditEntry:
    """The audit row of a request whose body did not validate: nothing was sent."""
    return AuditEntry(
        client=caller.client,
        drive=clip(drive, MAX_DRIVE_NAME),
        parameter=clip(parameter, MAX_PARAMETER_TEXT),
        index=0,
        outcome="invalid",
        token_id=identity,
        detail=problem,
    )


def locate(
    runtime: Runtime, drive: str, parameter: str, index: int | None
) -> tuple[DriveEntry, ParameterRef]:
    """The drive and the parameter by the drive's one name for it, with ``index`` applied."""
    entry = runtime.drives.get(drive)
    if entry is None:
        mastered_elsewhere(runtime, drive)
        raise ApiError(404, "unknown_drive", f"no drive named {drive!r}")
    if (held := runtime.snapshot.maintenance.get(drive)) is not None:
        why = f" ({held.reason})" if held.reason else ""
        raise ApiError(
            409, "in_maintenance", f"{drive} is in maintenance{why}: nothing goes out to it"
        )
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


def mastered_elsewhere(runtime: Runtime, drive: str) -> None:
    """409 ``not_master`` for a configured drive whose line this instance does not master
    now (hot standby), naming the instance that does and its URL (null: nobody now)."""
    masters = runtime.masters
    if masters is None or drive in runtime.drives:
        return
    line = masters.line_of(drive)
    if line is not None:
        _not_master(masters, line, f"{drive} is on line {line}")


def not_here(runtime: Runtime, drive: str, message: str) -> ApiError:
    """The refusal of a request for ``drive``, not among this instance's drives (now): 409
    ``not_master`` where another instance masters its line (hot standby; audited
    ``not_sent``), else 404 ``unknown_drive`` with ``message`` (audited ``invalid``)."""
    try:
        mastered_elsewhere(runtime, drive)
    except ApiError as elsewhere:
        elsewhere.outcome = "not_sent"
        return elsewhere
    unknown = ApiError(404, "unknown_drive", message)
    unknown.outcome = "invalid"
    return unknown


def line_mastered_elsewhere(runtime: Runtime, line: str) -> None:
    """409 ``not_master`` for a configured line this instance does not master now (hot
    standby), as :func:`mastered_elsewhere` for a drive."""
    masters = runtime.masters
    if masters is None or line in runtime.runners or line not in masters.lines():
        return
    _not_master(masters, line, f"line {line}")


def _not_master(masters: Masters, line: str, what: str) -> NoReturn:
    master = masters.master_of(line)
    name, url = (master.name, master.url) if master is not None else (None, None)
    said = (
        f"{what}, which instance {name} masters: ask there"
        if name is not None
        else f"{what}, which this instance does not master, nor knows an instance that does"
        " (etcd not reachable, or the line between masters): try again in a few seconds"
    )
    raise ApiError(409, "not_master", said, master=name, url=url)


def fit_index(ref: ParameterRef, fmt: ParameterDescription) -> ParameterRef:
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


def raise_for(result: JobResult) -> None:
    """The :class:`ApiError` of a job that did not succeed; nothing for one that did."""
    failure = http_failure(result.outcome, result.tally.telegrams if result.tally else 0)
    if failure is not None:
        raise ApiError(failure.status, failure.kind, failure.message, **failure.extra)


async def identified(tokens: TokenCheck, audit_writer: AuditWriter, caller: Caller) -> str | None:
    """The caller's token id; a refusal (counted, audited per address and minute) when the
    caller has no valid token."""
    try:
        return tokens.identify(caller)
    except ApiError as exc:
        exc.audit_incomplete = not await audit_writer.refused(caller.client, exc.kind)
        raise


async def attempted(audit_writer: AuditWriter, audit: AuditEntry, unchanged: str) -> Any:
    """Store ``audit``'s row before what it records is done: its row; 503 when the audit log
    cannot store it (``unchanged`` says what stays as it was)."""
    try:
        return await audit_writer.attempt(audit)
    except AuditUnavailable as exc:
        raise ApiError(
            503, "audit_unavailable", f"the audit log cannot record it ({exc}): {unchanged}"
        ) from None
