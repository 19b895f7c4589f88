"""A configuration reloaded without a restart: ``SIGHUP`` or ``POST /api/v1/reload``.

The file is read and checked as ``pkwbus run`` reads it. A file with a problem
changes nothing: the running configuration stays, the problems (each with its
place, as check-config names them) go to the log and to the caller, and
``pkwbus_config_last_reload_successful`` is 0 until a good one is loaded.

A good file applies what differs between the running configuration and the
new one, nothing else:

- a line whose bus settings (port, baud rate, framing, timeouts, retries,
  and on PROFIBUS the master's address, slot time and watchdog) are the same
  keeps its port open and its drives as they are (up or down, learned PKW
  length, descriptions, a DP slave's parametrisation, values); its telegrams
  go on without a gap;
- on such a line, a drive added starts, one removed stops (its series leave
  ``/metrics``), one whose polls alone changed keeps its state (a kept poll
  its due time, a changed interval applies from its next due time on, a new
  poll is due now), one changed otherwise (address, dialect, catalog,
  described parameters) is taken as a new drive: identified again, its
  descriptions from the description file;
- on a PROFIBUS line, slaves added, removed or changed other than in their
  polls change the bus's parameters (watchdog, slot time, the cycle): the line
  is closed and opened again alone, its slaves parametrised afresh;
- a line whose bus settings changed is closed and opened alone; lines added
  start, lines removed stop;
- the API's tokens and connection limit apply at once; ``listen``,
  ``audit_db``, ``history_db`` and ``log_format`` take a restart: a change of
  theirs is refused with that reason while the rest applies;
- a drive the API put in maintenance stays so; ``maintenance: true`` added in
  the file puts a drive in maintenance, taken away takes it out.

Reloads never overlap: one waits for the other. Each, and what it changed, is
logged (and audited by the caller, :mod:`pkwbus.service.http.reload`).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

from pydantic import BaseModel

from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.runner import LineRunner
from pkwbus.protocol.serial.telegram import Protocol
from pkwbus.service import config as cfg
from pkwbus.service.assembly.alarm_polls import alarm_parameters
from pkwbus.service.assembly.build import LinePlan, Parts
from pkwbus.service.assembly.history import Memory
from pkwbus.service.config import ConfigError
from pkwbus.service.runtime import DriveEntry, Runtime

__all__ = ["RESTART_ONLY", "ReloadOutcome", "Reloader"]

log = logging.getLogger("pkwbus.service.reload")

# What a running service cannot change: a reload keeps the running one and says so.
RESTART_ONLY = {
    "listen": "the HTTP address is bound at the start",
    "audit_db": "the audit log is opened at the start",
    "history_db": "the history database is opened at the start",
    "log_format": "the log's format is set at the start",
}
# A line's keys that are its drives' defaults, not its bus's settings.
DRIVE_DEFAULTS = frozenset({"describe", "alarms", "counters", "events", "events_every", "settings"})
REMOVED = "removed from the configuration by a reload"
REPLACED = "its configuration changed (a reload)"
CONFIGURED = "configuration"  # the reason of a maintenance the file asks for


@dataclass
class ReloadOutcome:
    """What a reload did: ``loaded`` (the file is the running configuration now), the
    file's ``problems`` when it was not, the ``changes`` it made, and the changes it
    ``refused`` (they take a restart)."""

    loaded: bool
    problems: list[str] = field(default_factory=list)
    changes: list[str] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)

    def summary(self) -> str:
        if not self.loaded:
            return "; ".join(self.problems)
        said = self.changes or ["nothing changed"]
        return "; ".join([*said, *(f"not applied: {r}" for r in self.refused)])


def _fields(model: BaseModel, without: Iterable[str] = ()) -> dict[str, Any]:
    skip = set(without)
    return {k: getattr(model, k) for k in type(model).model_fields if k not in skip}


class Reloader:
    """Reloads the service's configuration file into its running runtime."""

    def __init__(
        self,
        config: cfg.Config,
        reread: Callable[[], cfg.Config],
        runtime: Runtime,
        parts: Parts,
        memory: Memory | None = None,
        *,
        api: Callable[[cfg.Config], None] | None = None,
    ) -> None:
        self.config = config
        self._reread = reread
        self.runtime = runtime
        self.parts = parts
        self.memory = memory
        self._api = api  # applies the API's settings (tokens, connection limit)
        self.metrics = parts.config_metrics
        self._lock = asyncio.Lock()
        self._down: set[str] = set()  # lines a reload could not start: started by the next

    async def reload(self) -> ReloadOutcome:
        """Read the file again and apply what changed (see the module)."""
        async with self._lock:
            try:
                new = await asyncio.to_thread(self._reread)
            except ConfigError as exc:
                self.metrics.failed()
                log.error(
                    "reload: the configuration file has %d problem(s); the running"
                    " configuration stays:\n  %s", len(exc.problems), "\n  ".join(exc.problems),
                )  # fmt: skip
                return ReloadOutcome(False, list(exc.problems))
            new, refused = self._restart_only(new)
            changes, failed = await self._apply(new)
            self.config = new
            if failed:
                self.metrics.failed()
            else:
                self.metrics.loaded()
            outcome = ReloadOutcome(True, failed, changes, refused)
            for text in refused:
                log.warning("reload: not applied: %s", text)
            log.info("reload: %s", outcome.summary())
            return outcome

    def _restart_only(self, new: cfg.Config) -> tuple[cfg.Config, list[str]]:
        """``new`` with the running values of what takes a restart, and what those were."""
        kept: dict[str, Any] = {}
        refused = []
        for key, why in RESTART_ONLY.items():
            if getattr(new, key) != getattr(self.config, key):
                kept[key] = getattr(self.config, key)
                refused.append(f"{key}: {why}; it changes at the next restart")
        return (new.model_copy(update=kept) if kept else new), refused

    # ------------------------------------------------------------ applying

    async def _apply(self, new: cfg.Config) -> tuple[list[str], list[str]]:
        """Apply ``new`` over the running configuration: what changed, and what failed."""
        old_lines = {line.name: line for line in self.config.lines}
        new_lines = {line.name: line for line in new.lines}
        changes: list[str] = []
        failed: list[str] = []
        touched = (
            any(old_lines.get(n) != line for n, line in new_lines.items())
            or old_lines.keys() != new_lines.keys()
            or bool(self._down)
            or new.history_retention != self.config.history_retention
        )
        if touched and self.memory is not None:
            await self.memory.stop()  # watched afresh below, on the lines as they are then
        # Everything that goes first, then what comes: a drive that moves to another line
        # leaves the old one before it joins the new one.
        for name in sorted(old_lines.keys() - new_lines.keys()):
            await self._stop_line(name)
            changes.append(f"line {name} removed")
        starts: list[tuple[cfg.Line, str, dict[str, str]]] = []
        updates: list[tuple[cfg.Line, cfg.Line]] = []
        for name, line in new_lines.items():
            old = old_lines.get(name)
            if old is None or name in self._down:
                if old is not None:
                    await self._stop_line(name)
                starts.append((line, "added" if old is None else "started", {}))
            elif old == line:
                continue
            elif not self._in_place(old, line):
                held = self._held(old)
                await self._stop_line(name)
                starts.append((line, "reopened", held))
            else:
                changes += self._remove_drives(old, line)
                updates.append((old, line))
        for old, line in updates:
            changes += self._update_line(new, old, line)
        for line, how, held in starts:
            changes += await self._start_line(new, line, failed, how, held)
        if self._api is not None and (new.api != self.config.api):
            self._api(new)
            changes.append("API settings applied")
        if touched and self.memory is not None:
            self.memory.watch(new)
            await self.memory.start()
        return changes, failed

    def _in_place(self, old: cfg.Line, new: cfg.Line) -> bool:
        """Whether ``new`` can apply to ``old``'s running line without closing its port."""
        if _fields(old, {"drives", *DRIVE_DEFAULTS}) != _fields(new, {"drives", *DRIVE_DEFAULTS}):
            return False  # its bus settings changed
        if new.protocol is not Protocol.PROFIBUS:
            return True
        # A DP slave added, removed or changed changes the cycle and its parameters.
        if [d.name for d in old.drives] != [d.name for d in new.drives]:
            return False
        if _fields(old, {"drives"}) != _fields(new, {"drives"}):
            return False
        return all(
            _fields(a, {"poll", "maintenance"}) == _fields(b, {"poll", "maintenance"})
            for a, b in zip(old.drives, new.drives, strict=True)
        )

    def _held(self, line: cfg.Line) -> dict[str, str]:
        """The drives of ``line`` the API put in maintenance, with their reasons."""
        held = self.runtime.snapshot.maintenance
        return {
            d.name: held[d.name].reason
            for d in line.drives
            if d.name in held and held[d.name].reason != CONFIGURED
        }

    async def _stop_line(self, name: str) -> None:
        if name in self.runtime.runners:
            await self.runtime.stop_line(name)
        self.runtime.counts.pop(name, None)
        self.parts.counts.pop(name, None)
        self.parts.forget(name)
        self._down.discard(name)

    async def _start_line(
        self,
        config: cfg.Config,
        line: cfg.Line,
        failed: list[str],
        how: str,
        held: dict[str, str] | None = None,
    ) -> list[str]:
        plan = self.parts.plan(line)
        self.parts.show(config, plan)
        try:
            built = await self.parts.build(plan)
        except Exception as exc:  # a sim that cannot start, a GSD file gone since the check
            self.parts.forget(line.name)
            self._down.add(line.name)
            problem = f"line {line.name}: cannot start: {exc}"
            log.error("reload: %s", problem)
            failed.append(problem)
            return []
        for drive, reason in (held or {}).items():  # maintenance survives a reload
            built.runner.maintenance(drive, True, reason)
        self.runtime.counts[line.name] = built.counts
        if built.close is not None:
            self.runtime.closers[line.name] = built.close
        self.runtime.start_line(built.runner)
        return [f"line {line.name} {how}"]

    def _remove_drives(self, old: cfg.Line, new: cfg.Line) -> list[str]:
        """The drives gone from a running line."""
        runner = self.runtime.runners[new.name]
        assert isinstance(runner, LineRunner)
        news = {d.name for d in new.drives}
        gone = [d.name for d in old.drives if d.name not in news]
        for name in gone:
            self._remove(runner, new.name, name, REMOVED)
        return [f"line {new.name}: drive {name} removed" for name in gone]

    def _update_line(self, config: cfg.Config, old: cfg.Line, new: cfg.Line) -> list[str]:
        """Drives and polls of a running line, its port open throughout."""
        runner = self.runtime.runners[new.name]
        assert isinstance(runner, LineRunner)
        plan = self.parts.plan(new)
        specs = {s.name: s for s in plan.specs}
        entries = {e.name: e for e in plan.entries}
        counts = self.parts.counts[new.name]
        olds = {d.name: d for d in old.drives}
        said = f"line {new.name}:"
        changes = []
        defaults_same = _fields(old, {"drives"}) == _fields(new, {"drives"})
        for drive in new.drives:
            name = drive.name
            before = olds.get(name)
            if before is not None and before == drive and defaults_same:
                continue
            if before is not None and self._polls_only(runner, before, drive, specs[name],
                                                       entries[name]):  # fmt: skip
                if self._update_polls(config, runner, plan, specs[name], entries[name]):
                    changes.append(f"{said} drive {name}: polls changed")
            else:
                held = self._held(old).get(name) if before is not None else None
                if before is not None:
                    self._remove(runner, new.name, name, REPLACED)
                runner.add_drive(specs[name])
                counts.add_drive(name, drive.pkw_dialect)
                self.parts.show(config, plan, {name})
                if held is not None:
                    runner.maintenance(name, True, held)
                changes.append(f"{said} drive {name} {'added' if before is None else 'replaced'}")
            was = before is not None and before.maintenance
            if drive.maintenance and not was:
                runner.maintenance(name, True, CONFIGURED)
                changes.append(f"{said} drive {name} in maintenance")
            elif was and not drive.maintenance:
                held_now = self.runtime.snapshot.maintenance.get(name)
                if held_now is not None and held_now.reason == CONFIGURED:
                    runner.maintenance(name, False)
                    changes.append(f"{said} drive {name} out of maintenance")
        return changes

    def _polls_only(
        self, runner: LineRunner, old: cfg.Drive, new: cfg.Drive, spec: DriveSpec,
        entry: DriveEntry,
    ) -> bool:  # fmt: skip
        """Whether ``new`` differs from the running drive in its polls alone (what it is,
        where it is reached and what is described of it are the same)."""
        if _fields(old, {"poll", "maintenance"}) != _fields(new, {"poll", "maintenance"}):
            return False
        running = runner.planner.drive(new.name).spec
        return (
            self.runtime.drives[new.name].target == entry.target
            and running.form == spec.form
            and bool(running.describe) == bool(spec.describe)  # a describer, or none
        )

    def _update_polls(
        self,
        config: cfg.Config,
        runner: LineRunner,
        plan: LinePlan,
        spec: DriveSpec,
        entry: DriveEntry,
    ) -> bool:
        """The drive's new polls and described parameters, its state kept; whether they
        changed."""
        name = entry.name
        old = self.runtime.drives[name]
        described = runner.planner.drive(name).spec.describe
        if old.polls == entry.polls and described == spec.describe:
            return False
        # What the drive described stays; a poll kept keeps its decoding as described; a
        # parameter new to its descriptions waits for its own.
        entry.described.update(old.described)
        new = {t.pnu for t in spec.describe} - {t.pnu for t in described}
        entry.pending.intersection_update(old.pending | new)
        was = {(p.parameter, p.index): p for p in old.polls}
        for poll in entry.polls:
            key = (poll.parameter, poll.index)
            before = was.get(key)
            if before is not None and replace(before, every=poll.every) == poll:
                entry.formats[key] = old.formats.get(key, poll.fmt)
                entry.units[poll.parameter] = old.units.get(poll.parameter, poll.fmt.unit)
                if poll.parameter in old.sources:
                    entry.sources[poll.parameter] = old.sources[poll.parameter]
        keys = {(name, p.parameter, p.index) for p in entry.polls}
        self.parts.entries[name] = entry
        self.parts.collector.set_parameters(name, plan.infos_of(name))
        self.parts.board.forget(name, keep=keys)
        self.parts.board.watch(alarm_parameters(config, [entry]))
        self.parts.trends.forget(name, keep=keys)
        runner.update_polls(spec)
        return True

    def _remove(self, runner: LineRunner, line: str, drive: str, reason: str) -> None:
        runner.remove_drive(drive, reason)
        self.parts.counts[line].forget_drive(drive)
        self.parts.forget(line, drive)
