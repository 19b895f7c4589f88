"""The values' and the drives' topics and payloads, from the read model.

A polled value goes to ``{prefix}/{line}/{drive}/value/{parameter}[/{index}]`` as JSON
``{"v", "raw", "unit", "ts", "q"}``: ``ts`` when the drive answered (ms), ``q`` its
quality as the snapshot tells it (:func:`quality`). The index is in the topic where the
parameter is an array (its catalog says so), polled at several indexes, or polled at an
index other than 0. A drive's status, ``{prefix}/{line}/{drive}/status``, is
``maintenance``, ``online`` or ``offline``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from pkwbus.catalog.description import Value
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey, Snapshot
from pkwbus.service.mqtt.connection import publish_head
from pkwbus.service.runtime import DriveEntry

__all__ = [
    "ValueTopic",
    "ValueTopics",
    "drive_status",
    "index_shown",
    "quality",
    "stale_after",
    "value_json",
]


def stale_after(interval: float) -> float:
    """Seconds after which a value polled every ``interval`` is stale (the status page's
    rule): twice its interval, and at least its interval and 10 s."""
    return max(2 * interval, interval + 10.0)


def drive_status(snapshot: Snapshot, drive: str) -> str:
    """``maintenance``, ``online`` (it answers) or ``offline`` (not known to answer)."""
    if drive in snapshot.maintenance:
        return "maintenance"
    state = snapshot.drives.get(drive)
    return "online" if state is not None and state.up else "offline"


def quality(snapshot: Snapshot, drive: str, reading: Reading, interval: float, now: float) -> str:
    """``good``; ``maintenance`` or ``offline`` (the drive's status: the value is the last
    it gave); ``stale`` (older than :func:`stale_after` its poll interval)."""
    status = drive_status(snapshot, drive)
    if status != "online":
        return status
    if now - reading.timestamp > stale_after(interval):
        return "stale"
    return "good"


def index_shown(array: int | None, polled: int, index: int) -> bool:
    """Whether a value's topic carries its index: the parameter is an array (``array``
    elements, its catalog says), polled at several indexes (``polled``), or ``index`` is
    not 0."""
    return array is not None or polled > 1 or index != 0


def value_json(value: Value | None) -> str:
    """A value as JSON: a number that is not finite is null."""
    if value is None:
        return "null"
    if type(value) is float:
        return repr(value) if math.isfinite(value) else "null"
    if type(value) is int:
        return str(value)
    return json.dumps(value)


@dataclass(slots=True)
class ValueTopic:
    """One polled value's topic, its unit (as JSON) and poll interval, whether it is
    published on any change (``exact``: a value without a unit, a word of bits, a code, an
    option, where a deadband would hold back an alarm), and what was last published of it
    (``last``: None, nothing yet; ``sent``: the loop's time)."""

    drive: str
    topic: str
    unit: str
    interval: float
    exact: bool = False
    last: Value | None = None
    sent: float = -math.inf
    head: bytes = b""  # its PUBLISH packet's part before the payload (publish_head)

    def __post_init__(self) -> None:
        self.head = publish_head(self.topic)

    def payload(self, reading: Reading, q: str) -> bytes:
        raw = "null" if reading.raw is None else str(reading.raw)
        return (
            f'{{"v":{value_json(reading.value)},"raw":{raw},"unit":{self.unit},'
            f'"ts":{int(reading.timestamp * 1000)},"q":"{q}"}}'
        ).encode()

    def changed(self, value: Value, deadband: float) -> bool:
        """Whether ``value`` is to be published: the first, or beyond the deadband from the
        one last published (any change for a text, an exact value or with no deadband)."""
        last = self.last
        if last is None:
            return True
        numbers = type(value) in (int, float) and type(last) in (int, float)
        if deadband > 0 and numbers and not self.exact:
            return bool(abs(value - last) > deadband)  # type: ignore[operator]
        return value != last


class ValueTopics:
    """The topics of the runtime's polled values, made as each is first needed and
    forgotten with its drive."""

    def __init__(
        self, prefix: str, drives: Callable[[], Mapping[str, DriveEntry]], snapshot: Snapshot
    ) -> None:
        self.prefix = prefix
        self.drives = drives  # the runtime's now (its load's, as a reload swaps it)
        self.snapshot = snapshot
        self.topics: dict[ReadingKey, ValueTopic | None] = {}

    def get(self, key: ReadingKey) -> ValueTopic | None:
        found = self.topics.get(key, self)
        if found is self:
            found = self.topics[key] = self._make(key)
        return found  # type: ignore[return-value]

    def _make(self, key: ReadingKey) -> ValueTopic | None:
        drive, parameter, index = key
        entry = self.drives().get(drive)
        if entry is None:
            return None
        polls = [p for p in entry.polls if p.parameter == parameter]
        poll = next((p for p in polls if p.index == index), None)
        if poll is None:
            return None
        decoding = self.snapshot.decoding.get(drive)
        fmt = decoding.formats.get((parameter, index), poll.fmt) if decoding else poll.fmt
        topic = f"{self.status_topic(entry)[: -len('status')]}value/{parameter}"
        if index_shown(fmt.array, len(polls), index):
            topic += f"/{index}"
        exact = not fmt.unit or fmt.enumerates  # bits, codes, options: each change counts
        return ValueTopic(drive, topic, json.dumps(fmt.unit), poll.every, exact)

    def status_topic(self, entry: DriveEntry) -> str:
        return f"{self.prefix}/{entry.line}/{entry.name}/status"

    def forget(self, drive: str) -> None:
        """A drive's topics, made again from its entry when next needed (a reload)."""
        for key in [k for k in self.topics if k[0] == drive]:
            del self.topics[key]
