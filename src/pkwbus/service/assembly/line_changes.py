"""A reload's changes to the drives of a line that keeps running (its port open): drives
removed, added, replaced, and changed in place (:mod:`.reload`)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from typing import Any

from pydantic import BaseModel

from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.runner import LineRunner
from pkwbus.protocol.values import ParameterRef
from pkwbus.service import config as cfg
from pkwbus.service.assembly.build import LinePlan, Parts
from pkwbus.service.runtime import DriveEntry, Runtime

__all__ = ["CONFIGURED", "IN_PLACE", "REMOVED", "REPLACED", "DriveChanges", "fields"]

# A drive's keys that change it in place: the line sees them as polls and described
# parameters, the service as its entry, the watchers as what they watch.
IN_PLACE = frozenset(
    {"poll", "maintenance", "writable", "parameters", "alarms", "counters", "events",
     "events_every", "settings"}
)  # fmt: skip
# What each of those says when it changes, besides the polls and maintenance.
_SAID = {"writable": "writable parameters changed", "parameters": "parameter overrides changed",
         "alarms": "alarms changed", "counters": "counters changed", "events": "events changed",
         "events_every": "events_every changed", "settings": "settings changed"}  # fmt: skip
REMOVED = "removed from the configuration by a reload"
REPLACED = "its configuration changed (a reload)"
CONFIGURED = "configuration"  # the reason of a maintenance the file asks for


def fields(model: BaseModel, without: Iterable[str] = ()) -> dict[str, Any]:
    """A configuration model's fields, but ``without`` these."""
    skip = set(without)
    return {k: getattr(model, k) for k in type(model).model_fields if k not in skip}


class DriveChanges:
    """Applies a new configuration's drives to a running line."""

    def __init__(self, runtime: Runtime, parts: Parts) -> None:
        self.runtime = runtime
        self.parts = parts

    def removed(self, old: cfg.Line, new: cfg.Line) -> list[str]:
        """The drives gone from a running line."""
        runner = self.runtime.runners[new.name]
        assert isinstance(runner, LineRunner)
        news = {d.name for d in new.drives}
        gone = [d.name for d in old.drives if d.name not in news]
        for name in gone:
            self._remove(runner, new.name, name, REMOVED)
        return [f"line {new.name}: drive {name} removed" for name in gone]

    def update(self, config: cfg.Config, old: cfg.Line, new: cfg.Line) -> list[str]:
        """Drives and polls of a running line, its port open throughout."""
        runner = self.runtime.runners[new.name]
        assert isinstance(runner, LineRunner)
        plan = self.parts.plan(new)
        specs = {s.name: s for s in plan.specs}
        entries = {e.name: e for e in plan.entries}
        counts = self.parts.counts[new.name]
        olds = {d.name: d for d in old.drives}
        said = f"line {new.name}:"
        lined, drived = fields(old, {"drives"}), fields(new, {"drives"})
        # The drives' defaults the line gives (its bus settings are the same here).
        changes = [f"{said} {_SAID.get(k, f'{k} changed')}" for k in drived
                   if lined.get(k) != drived[k]]  # fmt: skip
        defaults_same = not changes
        for drive in new.drives:
            name = drive.name
            before = olds.get(name)
            if before is not None and before == drive and defaults_same:
                continue
            if before is not None and self._same_drive(runner, before, drive, specs[name],
                                                       entries[name]):  # fmt: skip
                changed = self._update_polls(runner, plan, specs[name], entries[name])
                told = [
                    text for k, text in _SAID.items() if getattr(before, k) != getattr(drive, k)
                ]
                if changed == "polls changed" or (changed and not told):
                    told.insert(0, changed)
                if told:
                    changes.append(f"{said} drive {name}: {', '.join(told)}")
                if drive.maintenance and not before.maintenance:
                    runner.maintenance(name, True, CONFIGURED)
                    changes.append(f"{said} drive {name} in maintenance")
                elif before.maintenance and not drive.maintenance:
                    # The file's (the API's own compares as unchanged: Reloader._api_kept).
                    runner.maintenance(name, False)
                    changes.append(f"{said} drive {name} out of maintenance")
                continue
            if before is not None:
                self._remove(runner, new.name, name, REPLACED)
            runner.add_drive(specs[name])
            counts.add_drive(name, drive.pkw_dialect)
            self.parts.show(plan, {name})
            if name in self.runtime.api_maintenance:  # it stays, on whichever line it is now
                self.runtime.show_maintenance(runner, name)
            elif drive.maintenance:
                runner.maintenance(name, True, CONFIGURED)
            changes.append(f"{said} drive {name} {'added' if before is None else 'replaced'}")
        return changes

    def _same_drive(
        self, runner: LineRunner[Any, Any], old: cfg.Drive, new: cfg.Drive, spec: DriveSpec,
        entry: DriveEntry,
    ) -> bool:  # fmt: skip
        """Whether ``new`` is the running drive with other polls, writable parameters,
        overrides or watch settings (what it is, where and how it is reached, and how it
        describes itself are the same): changed in place, its state kept."""
        if fields(old, IN_PLACE) != fields(new, IN_PLACE):
            return False
        running = runner.planner.drive(new.name).spec
        return (
            self.parts.entries[new.name].target == entry.target
            and running.form == spec.form
            and bool(running.describe) == bool(spec.describe)  # a describer, or none
        )

    def _update_polls(
        self,
        runner: LineRunner[Any, Any],
        plan: LinePlan,
        spec: DriveSpec,
        entry: DriveEntry,
    ) -> str | None:
        """The drive's new polls, described parameters and entry (its writable list, its
        overrides, its watch settings), its state kept, and the drive marked changed for the
        views; what changed of what the line sees (None: nothing)."""
        name = entry.name
        old = self.parts.entries[name]
        running = set(runner.planner.drive(name).spec.describe)
        changed = (
            "polls changed"
            if old.polls != entry.polls
            # a parameter no longer described stays known as it was (planning.reload)
            else ("changed in place" if not running.issuperset(spec.describe) else None)
        )
        # What the drive described stays in the read model; its writer takes the polls as
        # the planner decodes them now, and a parameter new to its descriptions waits for its
        # own (SnapshotWriter.update_polls). A value whose poll changed other than in its
        # interval is decoded otherwise now: its trend's points go with its value.
        was = {(p.parameter, p.index): replace(p, every=0.0) for p in old.polls}
        keys = {(name, p.parameter, p.index) for p in entry.polls
                if was.get((p.parameter, p.index)) == replace(p, every=0.0)}  # fmt: skip
        restated = self._restated(old, entry)
        self.parts.entries[name] = entry
        self.parts.collector.set_parameters(name, plan.infos_of(name))
        self.parts.trends.forget(name, keep=keys)
        runner.update_polls(spec, restated)
        return changed

    def _restated(self, old: DriveEntry, new: DriveEntry) -> frozenset[tuple[int, int]]:
        """The drive's latest values (PNU, subindex) that ``new`` decodes otherwise than
        ``old`` (its overrides' type, scaling or unit changed): a writable parameter or one
        read on demand, polled or not, is never shown in a format it was not decoded in."""
        if (old.parameters, old.layers) == (new.parameters, new.layers):
            return frozenset()
        snap, name = self.runtime.snapshot, new.name
        decoding = snap.decoding.get(name)
        described = decoding.described if decoding is not None else {}

        def decoded_as(entry: DriveEntry, ref: ParameterRef) -> tuple[object, ...]:
            fmt = entry.format_of(ref, described, snap.stated.get((name, ref.pnu)))
            return fmt.vtype, fmt.scaling, fmt.unit

        found = set()
        for _, pnu, sub in [k for k in snap.latest if k[0] == name]:
            refs = [ParameterRef(pnu, sub, ""), *([ParameterRef(pnu, None, "")] if not sub else [])]
            if any(decoded_as(old, ref) != decoded_as(new, ref) for ref in refs):
                found.add((pnu, sub))
        return frozenset(found)

    def _remove(self, runner: LineRunner[Any, Any], line: str, drive: str, reason: str) -> None:
        out = runner.remove_drive(drive, reason)  # an exchange of it out: the line's time
        self.parts.counts[line].forget_drive(drive, exchange_out=out)
        self.parts.forget(line, drive)
