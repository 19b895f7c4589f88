"""A drive's settings through the API: the last sweep, the baseline accepted, a backup
document, and a restore (:mod:`pkwbus.service.history.backup`).

- ``GET .../settings``: the last sweep, each setting with its baseline, since when it
  differs from it, and what the drive says of its factory setting.
- ``PUT .../settings/baseline`` (write token): the values last read become the
  baseline; audited (parameter ``settings/baseline``), stored before it is done.
- ``GET .../backup``: the drive's identity, its Danfoss active set-up (0-10, read now),
  the time, and every swept setting with its value.
- ``POST .../restore`` (write token): reads the drive's present values and plans the
  writes of what differs; a dry run stops there (each planned write audited as
  ``dry_run``); else each planned write goes through the one write path, in the
  backup's order (the ``writable`` list aside), audited and read back. A mismatch on
  read-back or a write that got no answer stops the restore; a write the drive refuses
  (the motor runs, say) is reported with the drive's reason and the restore goes on.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from pydantic import ValidationError

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.planning.jobs import JobKind
from pkwbus.master.planning.outcomes import Answered, Rejected
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.descriptions import (
    CHARACTERISTICS,
    Characteristics,
    DescriptionForm,
    form_of,
)
from pkwbus.protocol.values import ParameterRef, parse_parameter
from pkwbus.service.audit.log import AuditEntry
from pkwbus.service.audit.writer import AuditWriter
from pkwbus.service.history.backup import Backup, Planned, Present, plan_restore
from pkwbus.service.history.restore import carry_out
from pkwbus.service.history.store import HistoryError
from pkwbus.service.history.times import iso_time
from pkwbus.service.http.parameter_writes import WriteOrder, Writes
from pkwbus.service.runtime import DriveEntry, Runtime, Settings
from pkwbus.service.writes.checks import (
    INCOMPLETE,
    MAX_DRIVE_NAME,
    ApiError,
    Caller,
    TokenCheck,
    attempted,
    clip,
    described_format,
    identified,
    mastered_elsewhere,
)
from pkwbus.service.writes.reads import Reads

__all__ = ["BASELINE", "SETUP_PNU", "DriveSettings"]

BASELINE = "settings/baseline"  # the audit row's parameter of an accepted baseline
# Danfoss 0-10 Active Set-up ("[9] Multi set-ups ... in parameter 0-10 Active Set-up":
# Danfoss VLT CANopen MCA 105 manual, "Bit 13/14, Selection of set-up").
SETUP_PNU = 10
_TIMES = ("seen", "baseline_since", "changed_seen")


class DriveSettings:
    def __init__(
        self,
        runtime: Runtime,
        audit_writer: AuditWriter,
        tokens: TokenCheck,
        writes: Writes,
        reads: Reads,
    ) -> None:
        self.runtime = runtime
        self.audit_writer = audit_writer
        self._tokens = tokens
        self._writes = writes
        self._reads = reads

    def _swept(self, drive: str) -> tuple[DriveEntry, Settings]:
        entry = self.runtime.drives.get(drive)
        if entry is None:
            mastered_elsewhere(self.runtime, drive)
            raise ApiError(404, "unknown_drive", f"no drive named {drive!r}")
        settings = self.runtime.settings
        if settings is None or drive not in settings.swept:
            raise ApiError(
                404, "not_swept",
                f"the settings of {drive} are not swept (settings: off, or none to sweep)",
            )  # fmt: skip
        return entry, settings

    def view(self, drive: str) -> dict[str, Any]:
        _, settings = self._swept(drive)
        found = settings.view(drive)
        found["swept"] = _iso(found["swept"])
        for row in found["parameters"]:
            for key in _TIMES:
                row[key] = _iso(row[key])
        return found

    async def accept(self, drive: str, caller: Caller) -> dict[str, Any]:
        identity = await self._identify(caller)
        audit = AuditEntry(
            client=caller.client, drive=clip(drive, MAX_DRIVE_NAME), parameter=BASELINE,
            index=0, outcome="pending", token_id=identity,
        )  # fmt: skip
        try:
            _, settings = self._swept(drive)
        except ApiError as exc:
            audit.outcome = "invalid"
            exc.audit_incomplete = not await self.audit_writer.note(audit)
            raise
        row = await attempted(self.audit_writer, audit, "the baseline stays as it was")
        try:
            count = await settings.accept(drive)
        except HistoryError as exc:
            await asyncio.shield(self.audit_writer.outcome(row, outcome="error", detail=str(exc)))
            raise ApiError(
                503, "history_unavailable",
                f"the history database cannot store the baseline ({exc}): it stays as it was",
            ) from None  # fmt: skip
        stored = await asyncio.shield(
            self.audit_writer.outcome(row, outcome="ok", detail=f"{count} setting(s)")
        )
        body: dict[str, Any] = {"drive": drive, "accepted": count}
        if not stored:
            body["audit"] = INCOMPLETE
        return body

    async def backup(self, drive: str, of: str = "values") -> dict[str, Any]:
        """The drive's settings as a document: the values last read (``of`` ``values``; 409
        before a first complete sweep: no partial backup), or its baseline (``baseline``:
        what it held when last accepted, written by pkwbus or first swept - after a
        replacement of the same model, the failed drive's)."""
        entry, settings = self._swept(drive)
        found = settings.view(drive)
        if of == "values" and found["swept"] is None:
            raise ApiError(
                409, "not_swept_yet",
                f"no sweep of the settings of {drive} is complete yet: ask again in"
                f" {found['every']:g} s at most (or ?of=baseline)",
            )  # fmt: skip
        value, raw = ("value", "raw") if of == "values" else ("baseline", "baseline_raw")
        time_of = "seen" if of == "values" else "baseline_since"
        rows = [
            {k: r[k] for k in ("parameter", "index", "name", "unit")}
            | {"value": r[value], "raw": r[raw], "seen": _iso(r[time_of])}
            for r in found["parameters"]
            if r[raw] is not None
        ]
        document = Backup(
            drive=drive,
            line=entry.line,
            dialect=entry.target.dialect.name,
            catalog=found.get("catalog"),
            identity=found["identity"],
            setup=await self._setup(entry),
            time=iso_time(time.time()),
            settings=rows,  # type: ignore[arg-type]
        )
        return document.model_dump()

    async def restore(
        self, drive: str, body: dict[str, Any], dry_run: bool, store: pkw.Store, force: bool,
        caller: Caller,
    ) -> dict[str, Any]:  # fmt: skip
        await self._identify(caller)
        entry, settings = self._swept(drive)
        try:
            backup = Backup.model_validate(body)
        except ValidationError as exc:
            problems = "; ".join(
                f"{'.'.join(str(x) for x in e['loc'])}: {e['msg']}" for e in exc.errors()[:5]
            )
            raise ApiError(422, "invalid_backup", f"not a backup document: {problems}") from None
        present = {}
        for s in backup.settings:
            present[(s.parameter, s.index)] = await self._present(entry, s.parameter, s.index)
        view = settings.view(drive)
        plan, skipped = plan_restore(
            backup, present, target_identity=view["identity"], force=force,
            target_dialect=entry.target.dialect.name, target_catalog=view["catalog"],
        )  # fmt: skip

        async def write(step: Planned) -> dict[str, Any]:
            order = WriteOrder(step.new, step.index, store, verify=True, dry_run=dry_run,
                               restoring=True)  # fmt: skip
            return await self._write(drive, step.parameter, order, caller)

        results = await carry_out(plan, write)
        return {
            "drive": drive,
            "dry_run": dry_run,
            "plan": [p.as_dict() for p in plan],
            "skipped": [s.as_dict() for s in skipped],
            "results": results,
        }

    # ------------------------------------------------------------ steps

    async def _write(
        self, drive: str, parameter: str, order: WriteOrder, caller: Caller
    ) -> dict[str, Any]:
        """One planned write through the one write path, read back: its outcome."""
        try:
            done = await self._writes.write(drive, parameter, order, caller)
        except ApiError as exc:
            result: dict[str, Any] = {"outcome": exc.kind, "detail": str(exc)}
            if "fault" in exc.extra:
                result["fault"] = exc.extra["fault"]
            return result
        if order.dry_run:
            return {"outcome": "dry_run", "audit_id": done["audit_id"]}
        # Read back: a value other than the one written (or none) stops the restore.
        outcome = "ok" if done.get("verified") else "mismatch"
        return {"outcome": outcome, "audit_id": done["audit_id"]}

    async def _present(self, entry: DriveEntry, parameter: str, index: int) -> Present:
        """What the drive says of one setting of the backup now."""
        try:
            ref = entry.canonical(parse_parameter(parameter))
        except (LocalProtocolError, ValueError) as exc:
            return Present(None, ParameterDescription(), refused=str(exc))
        if index == 0 and ref.index is None:  # not an array: no index to send
            ref = ParameterRef(ref.pnu, None, ref.name)
        else:
            ref = ParameterRef(ref.pnu, index, ref.name)
        fmt = described_format(self.runtime, entry, ref)
        result = await self._reads.try_read(entry, ref, fmt)
        if isinstance(result.outcome, Rejected):
            return Present(None, fmt, refused=result.outcome.text)
        if not isinstance(result.outcome, Answered):
            return Present(None, fmt)
        decoding = self.runtime.snapshot.decoding.get(entry.name)
        described = decoding.described.get(ref.pnu) if decoding is not None else None
        read_only = fmt.prefix == "r" or bool(described is not None and described.read_only)
        characteristics = await self._characteristics(entry, ref.pnu)
        return Present(result.value, fmt, None, characteristics, read_only)

    async def _characteristics(self, entry: DriveEntry, pnu: int) -> Characteristics | None:
        """FC element 21 of the drive's parameter, read now (a replacement's may differ
        from what the sweep read of the drive before); None where it gives none."""
        if form_of(entry.target.dialect) is not DescriptionForm.DANFOSS_FC:
            return None
        request = pkw.read_description(entry.target.dialect, pnu, CHARACTERISTICS)
        result = await self.runtime.submit(entry.name, request, JobKind.READ,
                                           ParameterDescription())  # fmt: skip
        outcome = result.outcome
        if isinstance(outcome, Answered) and isinstance(outcome.response, pkw.DescriptionResponse):
            return Characteristics.of(outcome.response)
        return None

    async def _setup(self, entry: DriveEntry) -> int | None:
        """A Danfoss drive's active set-up (0-10), None where it gives none."""
        if form_of(entry.target.dialect) is not DescriptionForm.DANFOSS_FC:
            return None
        request = pkw.read(entry.target.dialect, SETUP_PNU)
        result = await self.runtime.submit(
            entry.name, request, JobKind.READ, ParameterDescription()
        )
        return result.raw if isinstance(result.outcome, Answered) else None

    async def _identify(self, caller: Caller) -> str | None:
        return await identified(self._tokens, self.audit_writer, caller)


def _iso(when: float | None) -> str | None:
    return None if when is None else iso_time(when)
