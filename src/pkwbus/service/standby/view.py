"""What this instance knows of the group's keys in etcd: each line's holder (its key's
value and lease) and the live instances, kept by one range and then one watch.

Keys: ``{prefix}/lines/{line}`` (value ``{"name", "url"}``, the holder's lease) and
``{prefix}/instances/{name}`` (the same value, the instance's registry lease).

Each read checks that etcd is still the store the view was read from: an etcd whose data
was lost (started anew, empty, on the same address) or restored from an older snapshot
answers with a revision below one already seen, another cluster with another cluster id.
The view is then forgotten whole and read anew (its revisions are the old store's: kept,
they would hide the new store's keys).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Final

from pkwbus.service.standby.etcd import Etcd, EtcdError, Event, KeyValue, b64, prefix_end, range_kvs

__all__ = ["RESYNC_EVERY", "Holder", "Master", "View", "keep_watching", "master_value"]

log = logging.getLogger("pkwbus.service.standby")

# The keys are read again this often, whatever the watch said: a stream that hangs
# without breaking (a connection dropped silently on the way) misses nothing longer.
RESYNC_EVERY: Final = 30.0
_WATCH_RETRY: Final = 0.5


@dataclass(frozen=True)
class Master:
    """Who masters a line (from its key's value): an instance's name and where the others
    send a user (its ``advertise``, None when not given)."""

    name: str
    url: str | None


@dataclass(frozen=True)
class Holder:
    master: Master
    lease: int
    revision: int  # the key's create revision


def master_value(name: str, url: str | None) -> bytes:
    return json.dumps({"name": name, "url": url}, separators=(",", ":")).encode()


def _master(value: bytes) -> Master:
    try:
        data = json.loads(value)
    except ValueError:
        data = None
    if not isinstance(data, dict) or not isinstance(data.get("name"), str):
        return Master(name="?", url=None)  # written by something else than pkwbus
    url = data.get("url")
    return Master(name=data["name"], url=url if isinstance(url, str) else None)


class View:
    """The lines' holders and the live instances under ``prefix``."""

    def __init__(self, prefix: str, me: str, clock: Callable[[], float]) -> None:
        self.prefix = prefix
        self.me = me
        self.lines_prefix = f"{prefix}/lines/"
        self.instances_prefix = f"{prefix}/instances/"
        self.clock = clock
        self.holders: dict[str, Holder] = {}
        self.changed_at: dict[str, int] = {}  # line -> revision of its key's last change seen
        self.instances: dict[str, Master] = {}
        self.free_since: dict[str, float] = {}
        self.joined: float | None = None  # when an instance last registered anew
        self.fresh = False  # read whole, and watched since
        self.revision = 0  # the highest revision of the store seen
        self.own_lease = 0  # the registry lease this instance registered on (0: not yet)
        self._twin_told = False  # another instance registered under this one's name: said
        self.cluster_id = ""  # the store's cluster, as its answers name it ("": not read yet)

    def line_key(self, line: str) -> str:
        return self.lines_prefix + line

    def instance_key(self, name: str) -> str:
        return self.instances_prefix + name

    def read_from(self, cluster_id: str, revision: int) -> str | None:
        """etcd answered a read with this header: None when it is the store the view was
        read from, else why not (the view is then forgotten: :meth:`reset`)."""
        why = None
        if self.cluster_id and cluster_id and cluster_id != self.cluster_id:
            why = f"cluster id changed from {self.cluster_id} to {cluster_id}"
        elif revision < self.revision:
            why = f"revision went back from {self.revision} to {revision}"
        if why is not None:
            self.reset()
        self.cluster_id = cluster_id or self.cluster_id
        return why

    def reset(self) -> None:
        """Everything forgotten, as before the first read: holders, instances, the
        revisions seen, when lines were seen free, when an instance joined."""
        self.holders.clear()
        self.changed_at.clear()
        self.instances = {}
        self.free_since.clear()
        self.joined = None
        self.fresh = False
        self.revision = 0
        self.cluster_id = ""

    def load(self, revision: int, lines: Iterable[KeyValue], instances: Iterable[KeyValue]) -> None:
        """Everything as read at ``revision`` (the watch goes on from the next). A line
        whose key we changed later than that keeps what we know."""
        now = self.clock()
        read = {kv.key.removeprefix(self.lines_prefix): kv for kv in lines}
        for line in set(self.holders) | set(read):
            if self.changed_at.get(line, 0) > revision:
                continue
            kv = read.get(line)
            if kv is not None:
                self._put_line(kv)
            elif self.holders.pop(line, None) is not None:
                self.free_since[line] = now
        old = set(self.instances)
        self.instances = {}
        for kv in instances:
            self.instances[name := kv.key.removeprefix(self.instances_prefix)] = _master(kv.value)
            self._check_twin(name, kv)
        if old and set(self.instances) - old - {self.me}:
            self.joined = now
        self.revision = max(self.revision, revision)

    def apply(self, events: Iterable[Event]) -> None:
        """A watch's events, in order; one older than what we know of its key is passed."""
        now = self.clock()
        for event in events:
            kv = event.kv
            self.revision = max(self.revision, kv.mod_revision)
            if kv.key.startswith(self.lines_prefix):
                line = kv.key.removeprefix(self.lines_prefix)
                if kv.mod_revision <= self.changed_at.get(line, 0):
                    continue
                if event.deleted:
                    self.changed_at[line] = kv.mod_revision
                    if self.holders.pop(line, None) is not None:
                        self.free_since[line] = now
                else:
                    self._put_line(kv)
            elif kv.key.startswith(self.instances_prefix):
                name = kv.key.removeprefix(self.instances_prefix)
                if event.deleted:
                    self.instances.pop(name, None)
                else:
                    if name not in self.instances and name != self.me:
                        self.joined = now
                    self.instances[name] = _master(kv.value)
                    self._check_twin(name, kv)

    def _check_twin(self, name: str, kv: KeyValue) -> None:
        """This instance's registry key put by another instance (on another lease): two
        instances share ``standby.name``; said once (each registers over the other, and the
        status pages and the 409s cannot tell them apart)."""
        if name != self.me or not self.own_lease or kv.lease in (0, self.own_lease):
            return
        if not self._twin_told:
            self._twin_told = True
            log.error(
                "hot standby: another instance registered as %r (lease %x, this one's %x):"
                " give each instance its own standby.name", name, kv.lease, self.own_lease,
            )  # fmt: skip

    def apply_put(self, kv: KeyValue) -> None:
        """A line's key as read now (a campaign lost: who won)."""
        if kv.mod_revision > self.changed_at.get(kv.key.removeprefix(self.lines_prefix), 0):
            self._put_line(kv)

    def _put_line(self, kv: KeyValue) -> None:
        line = kv.key.removeprefix(self.lines_prefix)
        self.holders[line] = Holder(_master(kv.value), kv.lease, kv.create_revision)
        self.changed_at[line] = max(self.changed_at.get(line, 0), kv.mod_revision)
        self.free_since.pop(line, None)

    def held_by(self, line: str, master: Master, lease: int, revision: int) -> None:
        """We put the line's key (a campaign won) at ``revision``."""
        self.holders[line] = Holder(master, lease, revision)
        self.changed_at[line] = max(self.changed_at.get(line, 0), revision)
        self.free_since.pop(line, None)

    def freed(self, line: str, revision: int) -> None:
        """We deleted the line's key at ``revision``."""
        self.changed_at[line] = max(self.changed_at.get(line, 0), revision)
        if self.holders.pop(line, None) is not None:
            self.free_since[line] = self.clock()

    def lease_of(self, line: str) -> int | None:
        holder = self.holders.get(line)
        return None if holder is None else holder.lease

    def free(self, line: str) -> bool:
        return line not in self.holders

    def note_free(self, lines: Iterable[str], since: float | None = None) -> None:
        """Lines not seen held are free from ``since`` (default: now) on, unless seen so
        before."""
        at = self.clock() if since is None else since
        for line in lines:
            if line not in self.holders:
                self.free_since.setdefault(line, at)


async def keep_watching(
    etcd: Etcd,
    view: View,
    kick: Callable[[], None],
    new_store: Callable[[], None] = lambda: None,
) -> None:
    """Keeps ``view`` as etcd has it, calling ``kick`` after each change; until cancelled.
    The view is ``fresh`` while the watch runs. ``new_store`` is called when etcd was found
    another store than the one read (logged), the view forgotten, before it is read anew."""
    while True:
        try:
            await _watch(etcd, view, kick, new_store)
            continue  # read anew after RESYNC_EVERY
        except EtcdError as exc:
            log.debug("hot standby: watch: %s", exc)
        view.fresh = False
        kick()
        await asyncio.sleep(_WATCH_RETRY)


async def _watch(
    etcd: Etcd, view: View, kick: Callable[[], None], new_store: Callable[[], None]
) -> None:
    """One read of the keys (both prefixes at one revision), then one watch from there."""
    prefixes = [view.lines_prefix, view.instances_prefix]
    ranges = [
        {"request_range": {"key": b64(p), "range_end": b64(prefix_end(p.encode()))}}
        for p in prefixes
    ]
    # the transaction's whole answer: its header names the store
    answer, _ = await etcd.call("/v3/kv/txn", {"compare": [], "success": ranges, "failure": []})
    answers = answer.get("responses")
    header = answer.get("header")
    if not isinstance(answers, list) or len(answers) != 2 or not isinstance(header, dict):
        raise EtcdError("etcd answered a read of the keys without its two ranges")
    try:
        revision = int(header["revision"])
    except (KeyError, TypeError, ValueError):
        raise EtcdError("etcd answered a read of the keys without its revision") from None
    why = view.read_from(str(header.get("cluster_id", "")), revision)
    if why is not None:
        log.warning("hot standby: etcd is not the store it was (%s): its view read anew", why)
        new_store()
    view.load(revision, range_kvs(answers[0]), range_kvs(answers[1]))
    async with etcd.watch(prefixes, revision + 1) as stream:
        view.fresh = True
        kick()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(RESYNC_EVERY):
                async for events in stream:
                    view.apply(events)
                    kick()
