"""A load of the configuration as the assembly puts it together: :class:`LoadBuilder` takes
the parts one by one (the lines' runners, the drives' memory, who masters the lines, what
starts and stops with them) and freezes them into a :class:`~pkwbus.service.runtime.Load`
once; :func:`change` makes the next load from the running one and swaps it in whole (the
start, a reload, a line won or lost in hot standby).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterator, Mapping
from contextlib import contextmanager

from pkwbus.master.events import Observer
from pkwbus.service.runtime import DriveEntry, History, LineTask, Load, Masters, Runtime, Settings

__all__ = ["LoadBuilder", "change"]


class LoadBuilder:
    """The parts of a load under way: mutable, the assembly's alone, frozen by
    :meth:`freeze`. ``drives``: the assembly's own drives as they change (Parts.entries),
    copied when frozen (None: the drives of ``load``)."""

    def __init__(
        self, load: Load | None = None, drives: Mapping[str, DriveEntry] | None = None
    ) -> None:
        load = load if load is not None else Load()
        self.runners: dict[str, LineTask] = dict(load.runners)
        self.drives: Mapping[str, DriveEntry] = drives if drives is not None else load.drives
        self.job_timeout = load.job_timeout
        self.history: History | None = load.history
        self.settings: Settings | None = load.settings
        self.masters: Masters | None = load.masters
        self.base: list[Observer] = list(load.base)
        self.watchers: list[Observer] = list(load.watchers)
        self.starters: list[Callable[[], Awaitable[None]]] = list(load.starters)
        self.cleanups: list[Callable[[], object]] = list(load.cleanups)
        self.closers: dict[str, Callable[[], object]] = dict(load.closers)

    def freeze(self) -> Load:
        """The load as built now; what changes in the builder after does not reach it."""
        return Load(
            runners=self.runners, drives=self.drives, job_timeout=self.job_timeout,
            history=self.history, settings=self.settings, masters=self.masters,
            base=tuple(self.base), watchers=tuple(self.watchers),
            starters=tuple(self.starters), cleanups=tuple(self.cleanups), closers=self.closers,
        )  # fmt: skip


@contextmanager
def change(
    runtime: Runtime,
    next_load: LoadBuilder | None = None,
    drives: Mapping[str, DriveEntry] | None = None,
) -> Iterator[LoadBuilder]:
    """A change of ``runtime``'s load: the builder of the next one, from the running one,
    frozen and swapped in at the end, also where the change failed half-way (what it
    started runs, and stops with the runtime). Given ``next_load``, a builder already under
    way: that one, frozen by whoever made it."""
    if next_load is not None:
        yield next_load
        return
    building = LoadBuilder(runtime.load, drives)
    try:
        yield building
    finally:
        runtime.swap(building.freeze())
