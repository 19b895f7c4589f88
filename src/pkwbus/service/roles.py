"""What the running service is given by its parts, as it uses them: a line's task, the drives'
history and settings, who masters each line, the values' trends (each implemented in
:mod:`pkwbus.service` or :mod:`pkwbus.master`, named here so that the runtime and the views
depend on no implementation)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from pkwbus.master.planning.carrier import Item, Preview
from pkwbus.master.planning.jobs import Job
from pkwbus.master.snapshot import ReadingKey

__all__ = ["History", "LineMaster", "LineTask", "Masters", "Settings", "Trends"]


class LineTask(Protocol):
    """One line's task: a :class:`~pkwbus.master.runner.LineRunner` of any bus."""

    name: str
    stopping: bool  # stopped (a reload opens its line again, or the service stops)

    def submit(self, job: Job) -> None: ...
    def preview(self, drive: str, item: Item) -> Preview: ...
    def maintenance(
        self, drive: str, on: bool, reason: str = "", since: float | None = None
    ) -> None: ...
    def settings_seen(self, drive: str, changed: int | None, swept: float | None) -> None: ...
    def stop(self) -> None: ...
    def forget(self) -> None: ...
    async def run(self) -> None: ...


class History(Protocol):
    """The drives' own log entries as kept (service.history.store.HistoryStore)."""

    def latest(
        self, *, drive: str | None = None, since: float | None = None, limit: int = 100
    ) -> list[Any]: ...


class Settings(Protocol):
    """The drives' settings as swept (service.history.settings.SettingsWatcher)."""

    @property
    def swept(self) -> Mapping[str, Any]: ...

    def view(self, drive: str) -> dict[str, Any]: ...

    async def accept(self, drive: str) -> int: ...

    async def written(
        self, drive: str, pnu: int, index: int, raw: int, value: Any, *, answered: bool = True
    ) -> None: ...


class LineMaster(Protocol):
    """Who masters a line (service.standby.Master): its instance's name and URL."""

    @property
    def name(self) -> str: ...

    @property
    def url(self) -> str | None: ...


class Masters(Protocol):
    """Who masters each configured line, in hot standby
    (service.assembly.standby_lines.StandbyLines)."""

    @property
    def etcd_up(self) -> bool: ...

    # Each configured line's drives, by line, in the configuration's order.
    def lines(self) -> Mapping[str, Sequence[str]]: ...
    def line_of(self, drive: str) -> str | None: ...  # None: no such drive
    def here(self, line: str) -> bool: ...  # whether this instance masters ``line`` now
    # Who masters ``line`` (this instance included); None: nobody now.
    def master_of(self, line: str) -> LineMaster | None: ...
    def takeovers(self, line: str) -> int: ...  # how often this instance took ``line``


class Trends(Protocol):
    """The last minutes of each polled value (service.metrics.trends.Trends)."""

    step: float  # seconds a point
    stamps: dict[str, int]  # per drive: changed each time a point changed but by time

    def points(self, key: ReadingKey, now: float) -> list[float | None]: ...
