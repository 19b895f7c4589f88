"""The lines of an instance in hot standby (interface "Hot standby"): a line runs here
only while this instance holds its lease.

The engine (:mod:`pkwbus.service.standby`) campaigns for the lines and tells each
change on the loop (``on_change(line, held)``). Held: the line is planned, shown and
built as at the start, its port given the lease's fence (no byte goes out once the
lease may have passed to another instance), and started. Released: its runner stops at
once, its port closes and nothing of it stays in the snapshot or ``/metrics``, as for a
line a reload removed; held again later, it starts from a fresh runner. The changes are
applied one after the other, and never while a reload applies (they share
:attr:`StandbyLines.lock`).

On the way out the lines stop with the runtime (their ports close), then
:meth:`StandbyLines.close` revokes the leases. A reload hands the engine the new lines
(:meth:`StandbyLines.reloaded`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

from pkwbus.link import closes_done
from pkwbus.link.fence import Fence, LineFence
from pkwbus.service import config as cfg
from pkwbus.service.assembly.build import Parts
from pkwbus.service.assembly.history import Memory
from pkwbus.service.assembly.line_marks import LineMarks
from pkwbus.service.assembly.loading import LoadBuilder, change
from pkwbus.service.config import StandbyConfig
from pkwbus.service.runtime import LineMaster, Runtime
from pkwbus.service.standby import Standby

__all__ = [
    "RETRY_FIRST",
    "RETRY_MAX",
    "STOP_GRACE",
    "Engine",
    "EngineFactory",
    "StandbyLines",
    "etcd_engine",
]

log = logging.getLogger("pkwbus.service.standby")

# How long a released line's exchange in flight may take to end before it is cancelled:
# its port's fence keeps it silent already.
STOP_GRACE = 0.5

# A line won that cannot start (a simulator that does not come up, a GSD file gone) is
# tried again while it is held: after RETRY_FIRST seconds, doubling up to RETRY_MAX.
RETRY_FIRST = 5.0
RETRY_MAX = 300.0
# How long a stop waits for its ports' closes before it revokes the lines' lease (s).
PORTS_CLOSED_WAIT = 3.0


class Engine(Protocol):
    """The hot standby's engine as the lines use it (service.standby.Standby)."""

    async def start(self) -> None: ...
    async def stop(self, *, revoke_lines: bool = True) -> None: ...
    def holds(self, line: str) -> bool: ...
    def fence(self, line: str) -> Fence: ...
    def master_of(self, line: str) -> LineMaster | None: ...
    @property
    def etcd_up(self) -> bool: ...
    def takeovers(self, line: str) -> int: ...
    def set_lines(self, lines: Sequence[str]) -> None: ...


# (the standby section, the lines' names, on_change) -> the engine
EngineFactory = Callable[[Any, Sequence[str], Callable[[str, bool], None]], Engine]


def etcd_engine(
    section: StandbyConfig, lines: Sequence[str], on_change: Callable[[str, bool], None]
) -> Engine:
    """The engine on etcd of the configuration's ``standby`` section."""
    return Standby(section, lines, on_change=on_change)


class StandbyLines:
    """Starts and stops the lines of ``config`` as this instance wins and loses them; who
    masters each line, for the API and the metrics (:class:`~pkwbus.service.runtime.Masters`)."""

    def __init__(
        self,
        config: cfg.Config,
        runtime: Runtime,
        parts: Parts,
        engine: EngineFactory,
        memory: Memory | None = None,
        next_load: LoadBuilder | None = None,
    ) -> None:
        """``next_load``: the runtime's next load, under way (None: swapped in here)."""
        self.config = config
        self.runtime = runtime
        self.parts = parts
        self.memory = memory
        self.lock = asyncio.Lock()  # one change at a time, never during a reload
        self._changes: set[asyncio.Task[None]] = set()
        self._closed = False
        self._lines: dict[str, cfg.Line] = {}
        self._drives: dict[str, str] = {}
        self._retries: dict[str, tuple[float, asyncio.TimerHandle | None]] = {}
        self._configure(config)
        section = config.standby
        self.engine = engine(section, list(self._lines), self.on_change)
        self.marks = _line_marks(self.engine, runtime, memory, self.lines, parts)
        parts.fence_of = self.fence_of
        with change(runtime, next_load) as next_load:
            next_load.masters = self
            next_load.starters.append(self.engine.start)
            # After the lines stopped (their ports closed): the leases revoked.
            next_load.cleanups.append(self.close)

    def _configure(self, config: cfg.Config) -> None:
        self.config = config
        self._lines = {line.name: line for line in config.lines}
        self._drives = {d.name: line.name for line in config.lines for d in line.drives}

    def fence_of(self, line: str) -> Fence:
        return LineFence(line, self.engine.fence(line))

    # ------------------------------------------------------------ runtime.Masters

    @property
    def etcd_up(self) -> bool:
        return self.engine.etcd_up

    def lines(self) -> Mapping[str, Sequence[str]]:
        return {name: [d.name for d in line.drives] for name, line in self._lines.items()}

    def line_of(self, drive: str) -> str | None:
        return self._drives.get(drive)

    def here(self, line: str) -> bool:
        return self.engine.holds(line)

    def master_of(self, line: str) -> LineMaster | None:
        return self.engine.master_of(line)

    def takeovers(self, line: str) -> int:
        return self.engine.takeovers(line)

    # ------------------------------------------------------------ changes

    def on_change(self, line: str, held: bool) -> None:
        """The engine's word (on the loop): ``line`` held by this instance, or not."""
        if not held:  # silent at once; the rest of the stop follows in order
            self._no_retry(line)
            runner = self.runtime.runners.get(line)
            if runner is not None:
                runner.stop()
        elif self.runtime.stopping:
            return
        task = asyncio.create_task(self._change(line, held), name=f"standby {line}")
        self._changes.add(task)
        task.add_done_callback(self._changed)

    def _changed(self, task: asyncio.Task[None]) -> None:
        self._changes.discard(task)
        if not task.cancelled() and (exc := task.exception()) is not None:
            log.error("hot standby: a line's change failed: %r", exc)

    async def _change(self, line: str, held: bool) -> None:
        """The line started or stopped, the runtime's next load swapped in at once (no wait
        between a runner started and its load: the service's stop finds it); then the
        drives' memory watched again, in the load after it."""
        async with self.lock:
            again = False
            with change(self.runtime, drives=self.parts.entries) as next_load:
                running = line in next_load.runners
                if held and not running and self.engine.holds(line) and line in self._lines:
                    if not self.runtime.stopping:
                        if line in self._shown():  # shown down: it could not start before
                            self.parts.forget(line)
                        again = await self._start(self._lines[line], next_load)
                elif not held and (running or line in self._shown()):
                    await self._stop(line, next_load)
                    again = True
            if again:
                with change(self.runtime, drives=self.parts.entries) as next_load:
                    again = await self._watch_again(next_load)
            if again and self.memory is not None:
                await self.memory.start()  # its watchers in the lines' outputs now

    def _shown(self) -> set[str]:
        return set(self.parts.line_of.values())

    async def _start(self, line: cfg.Line, next_load: LoadBuilder) -> bool:
        """Start ``line`` here, into ``next_load``; False when it cannot start (shown down)
        or the service stops."""
        parts = self.parts
        # The line's marks merged before it is planned (the describe book) and watched.
        kept = await self.marks.load(line.name) if self.marks is not None else {}
        plan = parts.plan(line)
        parts.show(plan)
        try:
            built = await parts.build(plan)
        except Exception as exc:  # a sim that cannot start, a GSD file gone since the check
            delay = self._retry_later(line.name)
            told = log.error if delay == RETRY_FIRST else log.debug  # once an outage
            told(
                "line %s: mastered here but cannot start: %s (tried again in %g s, and"
                " later, while this instance holds it)", line.name, exc, delay,
                extra={"line": line.name},
            )  # fmt: skip
            parts.down(plan)  # shown down until it starts or is released
            return False
        if line.name in self._retries:
            self._no_retry(line.name)
            log.warning("line %s: started at last", line.name, extra={"line": line.name})
        if self.runtime.stopping:
            closed = built.close() if built.close is not None else None
            if asyncio.iscoroutine(closed):
                await closed
            parts.forget(line.name)
            return False
        if built.close is not None:
            next_load.closers[line.name] = built.close
        next_load.runners[line.name] = built.runner
        self.runtime.start_line(built.runner)
        if self.marks is not None:  # the line's marks: maintenance kept, written while held
            self.marks.maintained(line.name, kept, built.runner)
            self.marks.hold(line.name)
        log.info("line %s: mastered here (hot standby)", line.name, extra={"line": line.name})
        return True

    def _retry_later(self, line: str) -> float:
        """A start of ``line`` tried again later, while held; the delay."""
        delay, handle = self._retries.get(line, (0.0, None))
        if handle is not None:
            handle.cancel()
        delay = RETRY_FIRST if delay == 0.0 else min(delay * 2, RETRY_MAX)
        again = asyncio.get_running_loop().call_later(delay, self._retry, line)
        self._retries[line] = (delay, again)
        return delay

    def _retry(self, line: str) -> None:
        delay, _ = self._retries.get(line, (0.0, None))
        self._retries[line] = (delay, None)
        if self.engine.holds(line) and line not in self.runtime.runners:
            self.on_change(line, True)

    def _no_retry(self, line: str) -> None:
        _, handle = self._retries.pop(line, (0.0, None))
        if handle is not None:
            handle.cancel()

    async def _stop(self, line: str, next_load: LoadBuilder) -> None:
        if self.marks is not None:  # the lease is gone: no more marks from here
            await self.marks.release(line, flush=False)
        if next_load.runners.pop(line, None) is not None:
            await self.runtime.stop_line(line, STOP_GRACE, next_load.closers.pop(line, None))
        self.parts.counts.pop(line, None)
        self.parts.forget(line)
        log.info("line %s: no longer mastered here (hot standby)", line, extra={"line": line})

    async def _watch_again(self, next_load: LoadBuilder) -> bool:
        """The drives' memory watched again, on the lines of ``next_load`` (that run here
        now); whether it was (then started by the caller once ``next_load`` is swapped in:
        its watchers are in the lines' outputs from then on)."""
        if self.memory is None or self.runtime.stopping:
            return False
        await self.memory.stop(final=False)
        self.memory.watch(self.config, next_load)
        return True

    # ------------------------------------------------------------ reload and stop

    async def reloaded(
        self, config: cfg.Config, next_load: LoadBuilder, *, watch: bool
    ) -> tuple[list[str], bool]:
        """A reload applied ``config`` (under :attr:`lock`), its next load ``next_load``: the
        engine campaigns for its lines; a held line that does not run yet starts (those
        started, as the reload says them). ``watch``: the drives' memory is watched again
        here (the reload does not do it itself); whether it was (the reload starts it once
        ``next_load`` is swapped in)."""
        self._configure(config)
        self.engine.set_lines(list(self._lines))
        if self.marks is not None:
            await self.marks.keep_only(self._lines)
        started = []
        for name, line in self._lines.items():
            if name not in next_load.runners and self.engine.holds(name):
                if name in self._shown():  # shown down: it could not start before
                    self.parts.forget(name)
                if await self._start(line, next_load):
                    started.append(f"line {name} started (mastered here)")
        watched = bool(started and watch) and await self._watch_again(next_load)
        return started, watched

    async def close(self) -> None:
        """The service stops, its lines stopped: the changes under way end, then the
        leases are revoked (once)."""
        if self._closed:
            return
        self._closed = True
        for line in list(self._retries):
            self._no_retry(line)
        if self._changes:
            await asyncio.wait(list(self._changes), timeout=10.0)
        for task in list(self._changes):
            task.cancel()
        if self.marks is not None:  # the leases still held: the marks written last
            with contextlib.suppress(Exception):
                await self.marks.close()
        # The ports were told to close; their closes run in a thread. The lines' lease is
        # revoked (the standby takes them at once) only once every one is done: a telegram
        # still draining from this instance's adapter must not meet the next master's.
        closed = await closes_done(PORTS_CLOSED_WAIT)
        if not closed:
            log.warning(
                "hot standby: a port still closing after %g s: the lines' lease is left to"
                " expire, the standby takes them then", PORTS_CLOSED_WAIT,
            )  # fmt: skip
        with contextlib.suppress(Exception):
            await self.engine.stop(revoke_lines=closed)


def _line_marks(
    engine: Engine,
    runtime: Runtime,
    memory: Memory | None,
    lines: Callable[[], Mapping[str, Sequence[str]]],
    parts: Parts,
) -> LineMarks | None:
    """The lines' drive-memory marks in etcd (:mod:`.line_marks`); None for an engine
    without marks (a test's)."""
    marks = getattr(engine, "marks", None)
    if marks is None:
        return None
    store = memory.stream.store if memory is not None else None
    path = store.path if store is not None else None
    history = None if path is None or str(path) == ":memory:" else path
    changes = store.changes if store is not None else None
    return LineMarks(marks, runtime, history, lambda line: lines().get(line, ()),
                     book=parts.book, saved=parts.kept, changes=changes)  # fmt: skip
