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
  ``/metrics``; an answer of it still out goes to its caller alone), one
  whose polls, writable list, overrides or watch settings changed keeps its
  state (a kept poll its due time, a changed interval applies from its next
  due time on, a new poll is due now: :mod:`.line_changes`), one changed
  otherwise (address, dialect, catalog, PKW settings) is taken as a new
  drive: identified again, its descriptions from the description file;
- on a PROFIBUS line, slaves added, removed or changed in their address or DP
  settings (a GSD file's content too) change the bus's parameters (watchdog,
  slot time, the cycle): the line is closed and opened again alone, its
  slaves parametrised afresh;
- a line whose bus settings changed is closed and opened alone; lines added
  start, lines removed stop; a line that cannot start is shown down and
  started by the next reload (the outcome ``partial``, the metric 0);
- the API's tokens and connection limit apply at once; ``listen``,
  ``audit_db``, ``history_db``, ``log_format`` and ``mqtt`` take a restart: a change of
  theirs is refused with that reason while the rest applies;
- a drive the API put in maintenance stays so (with its reason and since, on
  whichever line runs it, also where the API switched it while its line was being
  opened again); ``maintenance: true`` added in the file puts a drive in
  maintenance, taken away takes it out (but out of the API's maintenance).

A reload's changes apply at once with the next load's swap, after its last
await: a running line's drives change with their entries, and the lines it
opens start then, so that a request checked against a drive's entry never goes
to another drive (:mod:`pkwbus.service.writes.path`). Drives removed leave
first: a job for one ends cancelled, nothing sent.

Reloads never overlap: one waits for the other; none begins once the service
stops (:meth:`Reloader.close`). Each, and what it changed, is logged (and
audited by the caller, :mod:`pkwbus.service.http.reload`). An unexpected error
while applying is said in one line, and the next reload opens every line
afresh.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pkwbus.master.runner import LineRunner
from pkwbus.protocol.buses import Bus
from pkwbus.service import config as cfg
from pkwbus.service.assembly.build import Parts
from pkwbus.service.assembly.history import Memory
from pkwbus.service.assembly.line_changes import IN_PLACE, DriveChanges, fields
from pkwbus.service.assembly.loading import LoadBuilder, change
from pkwbus.service.assembly.standby_lines import StandbyLines
from pkwbus.service.config import ConfigError
from pkwbus.service.http.reload import ReloadRefused
from pkwbus.service.runtime import Runtime

__all__ = ["RESTART_ONLY", "ReloadOutcome", "ReloadRefused", "Reloader"]

log = logging.getLogger("pkwbus.service.reload")

# What a running service cannot change: a reload keeps the running one and says so.
RESTART_ONLY = {
    "listen": "the HTTP address is bound at the start",
    "audit_db": "the audit log is opened at the start",
    "history_db": "the history database is opened at the start",
    "log_format": "the log's format is set at the start",
    "standby": "hot standby is set up at the start",
    "mqtt": "the MQTT connection is made at the start",
}
# A line's keys that are its drives' defaults, not its bus's settings.
DRIVE_DEFAULTS = frozenset({"describe", "alarms", "counters", "events", "events_every", "settings"})


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
        said = self.changes or ([] if self.problems else ["nothing changed"])
        return "; ".join([*said, *self.problems, *(f"not applied: {r}" for r in self.refused)])

    @property
    def outcome(self) -> str:
        """The audit row's outcome: ``ok``; ``invalid`` (a file with problems, nothing
        changed); ``partial`` (applied but for lines that could not start)."""
        return "invalid" if not self.loaded else ("partial" if self.problems else "ok")


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
        gate: StandbyLines | None = None,
    ) -> None:
        self.config = config
        # Hot standby: only the lines running here change here; the others start, with
        # the new configuration, when this instance wins them.
        self.gate = gate
        self._reread = reread
        self.runtime = runtime
        self.parts = parts
        self.memory = memory
        self._api = api  # applies the API's settings (tokens, connection limit)
        self.metrics = parts.config_metrics
        self._drives = DriveChanges(runtime, parts)
        self._lock = asyncio.Lock()
        self._down: set[str] = set()  # lines a reload could not start: started by the next
        self._opened: list[LineRunner[Any, Any]] = []  # lines this reload built, to start
        self.after: list[Callable[[], None]] = []  # told once a reload applied (MQTT)
        self.closing = False

    async def close(self) -> None:
        """No reload from now on (the service stops); one under way finishes first."""
        self.closing = True
        async with self._lock:
            pass

    async def reload(self) -> ReloadOutcome:
        """Read the file again and apply what changed (see the module); ReloadRefused once
        the service is stopping."""
        if self.closing:
            raise ReloadRefused("the service is stopping")
        async with self._lock:
            if self.closing:
                raise ReloadRefused("the service is stopping")
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
            before = set(self.runtime.api_maintenance)  # what the API keeps in maintenance
            touched = self._touched(new)
            if touched and self.memory is not None:
                # Watched afresh below, on the lines as they are then.
                await self.memory.stop(final=False)
            changes: list[str] = []
            failed: list[str] = []
            watched = touched  # the drives' memory watched again: started once swapped in
            gate = self.gate.lock if self.gate is not None else contextlib.nullcontext()
            try:
                async with gate:
                    # The next load, built from the running one and swapped in whole.
                    with change(self.runtime, drives=self.parts.entries) as next_load:
                        try:
                            updates, at = await self._apply(new, changes, failed, next_load)
                            if self.gate is not None:
                                started, again = await self.gate.reloaded(
                                    new, next_load, watch=not touched
                                )
                                changes += started
                                watched = watched or again
                            # After the last await, at once with the swap of the next load:
                            # the running lines' drives change as their entries do (a write
                            # checked against a drive's entry never goes to another drive).
                            for old, line in updates:  # said where they were before
                                kept = self._api_kept(old, line)
                                said = self._drives.update(new, kept, line)
                                changes[at:at] = said
                                at += len(said)
                        finally:
                            # The lines opened start now, and every line holds what the API
                            # keeps in maintenance now (also what it switched meanwhile),
                            # before a line sends anything (at the next await).
                            for runner in self._opened:
                                self.runtime.start_line(runner)
                            self._opened.clear()
                            self._keep_maintenance(new, next_load, before)
                            if touched and self.memory is not None:
                                self.memory.watch(new, next_load)
            except Exception as exc:  # a defect: say so; the next reload opens them afresh
                self._down.update(line.name for line in new.lines)
                problem = f"the change could not be applied ({exc!r}): every line is opened" \
                    " again by the next reload"  # fmt: skip
                log.error("reload: %s", problem)
                failed.append(problem)
            finally:
                self.config = new
                self.parts.lines = [line.name for line in new.lines]
                if watched and self.memory is not None:
                    await self.memory.start()
                for told in self.after:
                    told()
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
            if getattr(new, key, None) != getattr(self.config, key, None):
                kept[key] = getattr(self.config, key, None)
                refused.append(f"{key}: {why}; it changes at the next restart")
        return (new.model_copy(update=kept) if kept else new), refused

    # ------------------------------------------------------------ applying

    def _touched(self, new: cfg.Config) -> bool:
        """Whether ``new`` changes a line (the watchers of the drives' memory follow)."""
        old_lines = {line.name: line for line in self.config.lines}
        new_lines = {line.name: line for line in new.lines}
        return (
            any(old_lines.get(n) != line for n, line in new_lines.items())
            or old_lines.keys() != new_lines.keys()
            or bool(self._down)
            or new.history_retention != self.config.history_retention
        )

    def _api_kept(self, old: cfg.Line, line: cfg.Line) -> cfg.Line:
        """``old`` as a running line's drives compare to ``line``'s: where the API keeps a
        drive in maintenance, with ``line``'s ``maintenance`` (the file's flag added or taken
        away leaves the API's maintenance as it is: its reason and since stay)."""
        kept = self.runtime.api_maintenance
        flags = {d.name: d.maintenance for d in line.drives if d.name in kept}
        drives = [
            d.model_copy(update={"maintenance": flags[d.name]}) if d.name in flags else d
            for d in old.drives
        ]
        return old.model_copy(update={"drives": drives}) if flags else old

    def _keep_maintenance(self, new: cfg.Config, next_load: LoadBuilder, before: set[str]) -> None:
        """The API's maintenance on the lines as they run from now on: what it keeps, with
        its reason and since, also where the API switched a drive while its line was being
        opened again (of ``before``, those it took out meanwhile are out unless the file
        keeps them); a drive gone from the configuration leaves it."""
        kept = self.runtime.api_maintenance
        configured = {d.name: d.maintenance for line in new.lines for d in line.drives}
        for name in [name for name in kept if name not in configured]:
            self.runtime.end_maintenance(name)
        for name in sorted(before | kept.keys()):
            entry = next_load.drives.get(name)
            runner = next_load.runners.get(entry.line) if entry is not None else None
            if runner is not None:
                self.runtime.show_maintenance(runner, name, configured=configured.get(name, False))

    async def _apply(
        self, new: cfg.Config, changes: list[str], failed: list[str], next_load: LoadBuilder
    ) -> tuple[list[tuple[cfg.Line, cfg.Line]], int]:
        """Apply ``new`` over the running configuration, into the next load ``next_load``: what
        changed into ``changes``, lines that could not start into ``failed``. The running
        lines whose drives change in place, changed after every await (:meth:`reload`), and
        where in ``changes`` that is said."""
        old_lines = {line.name: line for line in self.config.lines}
        new_lines = {line.name: line for line in new.lines}
        # Everything that goes first, then what comes: a drive that moves to another line
        # leaves the old one before it joins the new one.
        for name in sorted(old_lines.keys() - new_lines.keys()):
            await self._stop_line(name, next_load)
            changes.append(f"line {name} removed")
        starts: list[tuple[cfg.Line, str]] = []
        updates: list[tuple[cfg.Line, cfg.Line]] = []
        for name, line in new_lines.items():
            old = old_lines.get(name)
            if self.gate is not None and name not in next_load.runners:
                # Not mastered here now: started by the gate when it is; said all the same.
                if old is None:
                    changes.append(f"line {name} added (started where it is mastered)")
                elif old != line:
                    changes.append(f"line {name} changed (applied where it is mastered)")
                continue
            if old is None or name in self._down:
                if old is not None:
                    await self._stop_line(name, next_load)
                starts.append((line, "added" if old is None else "started"))
            elif old == line and not self._gsd_changed(line):
                continue
            elif not self._in_place(old, line):
                await self._stop_line(name, next_load)
                starts.append((line, "reopened"))
            else:
                changes += self._drives.removed(old, line)
                updates.append((old, line))
        at = len(changes)
        for line, how in starts:
            changes += await self._start_line(new, line, failed, how, next_load)
        if self._api is not None and (new.api != self.config.api):
            self._api(new)
            changes.append("API settings applied")
        return updates, at

    def _in_place(self, old: cfg.Line, new: cfg.Line) -> bool:
        """Whether ``new`` can apply to ``old``'s running line without closing its port."""
        if fields(old, {"drives", *DRIVE_DEFAULTS}) != fields(new, {"drives", *DRIVE_DEFAULTS}):
            return False  # its bus settings changed
        if new.protocol is not Bus.PROFIBUS:
            return True
        # A DP slave added, removed or changed (its address, its DP settings, its GSD
        # file's content) changes the cycle and the slaves' parameters.
        if [d.name for d in old.drives] != [d.name for d in new.drives]:
            return False
        same = all(
            fields(a, IN_PLACE) == fields(b, IN_PLACE)
            for a, b in zip(old.drives, new.drives, strict=True)
        )
        return same and not self._gsd_changed(new)

    def _gsd_changed(self, line: cfg.Line) -> bool:
        """Whether a PROFIBUS line's slaves resolve to other settings than when it was
        built (a GSD file changed under the same name)."""
        if not isinstance(line, cfg.ProfibusLine):
            return False
        built = self.parts.resolved.get(line.name)
        return built is not None and built != tuple(d.dp.settings()[0] for d in line.drives)

    async def _stop_line(self, name: str, next_load: LoadBuilder) -> None:
        if next_load.runners.pop(name, None) is not None:
            await self.runtime.stop_line(name, close=next_load.closers.pop(name, None))
        self.parts.counts.pop(name, None)
        self.parts.forget(name)
        self._down.discard(name)

    async def _start_line(
        self,
        config: cfg.Config,
        line: cfg.Line,
        failed: list[str],
        how: str,
        next_load: LoadBuilder,
    ) -> list[str]:
        plan = self.parts.plan(line)
        self.parts.show(plan)
        try:
            built = await self.parts.build(plan)
        except Exception as exc:  # a sim that cannot start, a GSD file gone since the check
            self._down.add(line.name)
            self.parts.down(plan)  # shown down (its alerts fire), started by the next reload
            problem = f"line {line.name} {how} but cannot start: {exc}"
            log.error("reload: %s", problem)
            failed.append(problem)
            return []
        if built.close is not None:
            next_load.closers[line.name] = built.close
        next_load.runners[line.name] = built.runner
        self._opened.append(built.runner)  # started once the reload applied (:meth:`reload`)
        return [f"line {line.name} {how}"]
