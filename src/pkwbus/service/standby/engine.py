"""The hot standby engine: campaigns for the lines in etcd, holds them on a lease, tells.

**One lease for all the lines of an instance** (and one more for its registry key).
Nothing moves most of the time, and then the lines' keys cost one renewal every lease /
3 per instance whatever its number of lines (per line: 3 / (lease x lines) requests a
second), where a lease per line would cost 3 / lease per line. A line still moves
alone: it is given away by deleting its key (in a transaction that checks the key is on
our lease), and taken with the taker's lease. What a shared lease binds together - all
the lines are lost at once when renewals fail - is bound anyway, since every renewal
travels the same way. The registry's lease is separate so that the lines' lease can be
given up and granted anew (when etcd forgot it) without the instance leaving the group,
and so that revoking it first on the way out tells the others at once that they may
take all.

A line is **held** while its key carries our lines' lease, as last read from etcd, and
that lease's fence is open; :class:`~pkwbus.service.standby.fence.LineLeaseFence` says
so to the port. Held and no longer held are told with ``on_change`` on the loop. A
campaign is a transaction putting the key if it has never been created
(``create_revision == 0``). One watch stream on the lines' and the instances' keys tells
of a line released within a round trip; the keys are read anew every
:data:`~pkwbus.service.standby.view.RESYNC_EVERY` seconds, in case a stream hangs without breaking.

etcd away: the lease's fence closes lease - margin after the last renewal sent (the
lines are told lost), ``etcd_up`` is False, logged once per outage; when etcd answers
again and still has the lease, its lines are held again (their keys never left),
otherwise they are campaigned for anew.

etcd another store (its data lost, restored from an older snapshot: the view's read
finds its revision gone back, or another cluster id): its view is read anew, every line
is told lost and none is held or campaigned for during one lease - the masters of the
old store hold their lines on its leases until their fences close, within a lease -,
then the lines are campaigned for as at a start. Leases the new store does not know are
granted anew by their keepers (a renewal answered with no TTL).
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Final

from pkwbus.link.fence import FENCE_CLOCK
from pkwbus.service.config.model import StandbyConfig
from pkwbus.service.standby.etcd import Etcd, EtcdError, b64, range_kvs
from pkwbus.service.standby.fence import LeaseClock, LineLeaseFence, request_timeout
from pkwbus.service.standby.keeper import LeaseKeeper
from pkwbus.service.standby.marks import Marks
from pkwbus.service.standby.share import Policy, Situation, share
from pkwbus.service.standby.view import Master, View, keep_watching, master_value
from pkwbus.waiting import wait_event

__all__ = ["ORPHAN_GRACE", "RELEASE_GRACE", "Standby"]

log = logging.getLogger("pkwbus.service.standby")

# A line given away is deleted from etcd this long after its port was told to stop: the
# port refuses every write from the moment it is told, and a telegram already handed to
# the driver is out by then (255 bytes at 9600 baud take 0.3 s).
RELEASE_GRACE: Final = 0.5
# A free line is anyone's after this (share.Policy, orphans).
ORPHAN_GRACE: Final = 0.5
# The engine looks at its state at least this often (orphans, releases due).
_TICK: Final = 0.2
_STOP_WAIT: Final = 5.0  # seconds stop() waits for its tasks to end


class Standby:
    """Hot standby of ``lines`` by the group of ``config`` (see the module's docstring)."""

    def __init__(
        self,
        config: StandbyConfig,
        lines: Sequence[str],
        *,
        on_change: Callable[[str, bool], None],
        clock: Callable[[], float] = FENCE_CLOCK,
    ) -> None:
        self.config = config
        self.name = config.name
        self.me = Master(config.name, config.advertise)
        self._lines = list(dict.fromkeys(lines))
        self._on_change = on_change
        self._clock = clock
        self.etcd = Etcd(config.etcd, request_timeout(config.lease), clock)
        self.view = View(config.prefix, config.name, clock)
        self.view.note_free(self._lines)
        self.lease = LeaseKeeper(
            self.etcd, config.lease, "lines", self._kick, self._failed, self._answered
        )
        self.registry = LeaseKeeper(
            self.etcd, config.lease, "registry", self._kick, lambda _: None, lambda: None
        )
        self.policy = Policy(
            orphan_grace=ORPHAN_GRACE,
            retake_after=config.lease,
            window=max(30.0, 10 * config.lease),
        )
        self._held: dict[str, LeaseClock] = {}  # line -> the fence it is held on
        self._held_lease: dict[str, int] = {}
        self._releasing: dict[str, float] = {}  # line -> when it was told lost
        self._given: dict[str, float] = {}
        self._orphans: set[str] = set()
        self._joined_seen: float | None = None
        self._registered: int | None = None  # the registry lease our key was put with
        self._takeovers: Counter[str] = Counter()
        self._fences: dict[str, LineLeaseFence] = {}
        self._etcd_up = False
        self._outage_told = False
        self._wake = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self._stopped = False
        self._quiet_until = 0.0  # nothing held or campaigned for before (etcd another store)
        self._store = 0  # how many times etcd was found another store
        self.marks = Marks(self)

    # ------------------------------------------------------------------ the contract

    async def start(self) -> None:
        """Registers the instance and campaigns, in the background; never raises for
        etcd's trouble (``etcd_up`` False, logged once, tried again)."""
        if self._tasks or self._stopped:
            return
        runs = {
            "lease": self.lease.run(),
            "registry": self.registry.run(),
            "watch": keep_watching(self.etcd, self.view, self._kick, self._new_store),
            "campaign": self._campaigning(),
        }
        for what, run in runs.items():
            task = asyncio.create_task(run, name=f"standby {what}")
            task.add_done_callback(self._ended)
            self._tasks.append(task)

    async def stop(self, *, revoke_lines: bool = True) -> None:
        """Stops campaigning, revokes the registry's lease and then the lines' (their
        keys deleted: the others take the lines at once; not ``revoke_lines``: left to
        expire). The caller closed the ports first; ``on_change`` is not called, every
        fence is closed."""
        self._stopped = True
        for task in self._tasks:
            task.cancel()
        if self._tasks:
            _, stuck = await asyncio.wait(self._tasks, timeout=_STOP_WAIT)
            for task in stuck:  # never expected: told, and the revocations go on
                log.error("hot standby: %s did not stop within %g s", task.get_name(), _STOP_WAIT)
        self._tasks = []
        self._held.clear()
        self._held_lease.clear()
        if not revoke_lines:
            self.lease.forget()  # left to expire, never revoked later
        for keeper in (self.registry, self.lease):
            try:
                await keeper.revoke()
            except EtcdError as exc:
                log.warning("hot standby: the %s lease not revoked: %s", keeper.what, exc)
        await self.etcd.aclose()

    def holds(self, line: str) -> bool:
        fence = self._held.get(line)
        return fence is not None and fence.is_open()

    def fence(self, line: str) -> LineLeaseFence:
        fence = self._fences.get(line)
        if fence is None:
            fence = self._fences[line] = LineLeaseFence(line, self._held.get)
        return fence

    def master_of(self, line: str) -> Master | None:
        """Who masters ``line``: this instance while it holds it, else the holder etcd
        names (None: nobody, this instance's key while it does not hold it, or not known:
        etcd is not watched now, and what it named last may have expired since)."""
        if self.holds(line):
            return self.me
        holder = self.view.holders.get(line)
        if holder is None or holder.master.name == self.name or not self.view.fresh:
            return None
        return holder.master

    @property
    def etcd_up(self) -> bool:
        return self._etcd_up

    def takeovers(self, line: str) -> int:
        return self._takeovers[line]

    def set_lines(self, lines: Sequence[str]) -> None:
        """The lines after a reload: new ones campaigned for, gone ones given away."""
        self._lines = list(dict.fromkeys(lines))
        self.view.note_free(self._lines)
        self._kick()

    @property
    def lines(self) -> list[str]:
        return list(self._lines)

    def held_lease(self, line: str) -> int | None:
        """The lease ``line`` is held on, while held (for :class:`Marks`)."""
        return self._held_lease.get(line) if self.holds(line) else None

    # ------------------------------------------------------------------ state

    def _kick(self) -> None:
        self._wake.set()

    def _answered(self) -> None:
        if not self._etcd_up and self._outage_told:
            log.warning("hot standby: etcd answers again")
        self._etcd_up = True
        self._outage_told = False

    def _failed(self, exc: EtcdError) -> None:
        self._etcd_up = False
        if not self._outage_told:
            self._outage_told = True
            log.warning(
                "hot standby: etcd unreachable (%s); this instance masters no line until it"
                " answers (tried again quietly)",
                exc,
            )
        self._kick()

    def _new_store(self) -> None:
        """etcd is another store than the one read (the view forgotten, see the module's
        docstring): what was known of the old one forgotten, every line told lost."""
        self._store += 1
        self._quiet_until = self._clock() + self.config.lease
        self._releasing.clear()
        self._given.clear()
        self._orphans.clear()
        self._joined_seen = None
        self._registered = None
        # free since the quiet ends: each takes its share first, as at a start
        self.view.note_free(self._lines, since=self._quiet_until)
        self._reconcile()
        self._kick()

    def _ended(self, task: asyncio.Task[None]) -> None:
        if not task.cancelled() and (exc := task.exception()) is not None:
            log.error("hot standby: %s ended: %r", task.get_name(), exc)

    def _reconcile(self) -> None:
        """Tell each line lost or won, as the view and the lease say now."""
        if self.view.joined != self._joined_seen:  # lines taken as orphans may go now
            self._joined_seen = self.view.joined
            self._orphans.clear()
        quiet = self._clock() < self._quiet_until
        lease = self.lease.id if self.lease.is_open() and not quiet else None
        for line in list(self._held):
            if (
                lease is None
                or self._held_lease.get(line) != lease
                or self.view.lease_of(line) != lease
                or line in self._releasing
                or line not in self._lines
            ):
                del self._held[line]
                self._held_lease.pop(line, None)
                self._orphans.discard(line)
                self._tell(line, False)
        if lease is None or not self.view.fresh or self._stopped:
            return
        for line in self._lines:
            if (
                line not in self._held
                and line not in self._releasing
                and self.view.lease_of(line) == lease
            ):
                self._held[line] = self.lease.fence
                self._held_lease[line] = lease
                self._takeovers[line] += 1
                self._tell(line, True)

    def _tell(self, line: str, held: bool) -> None:
        log.info(
            "hot standby: line %s %s",
            line,
            "held by this instance" if held else "no longer held by this instance",
            extra={"line": line},
        )
        try:
            self._on_change(line, held)
        except Exception:
            log.exception("hot standby: on_change(%r, %r) failed", line, held)

    # ------------------------------------------------------------------ campaigns

    async def _campaigning(self) -> None:
        while not self._stopped:
            await wait_event(self._wake, _TICK)
            self._wake.clear()
            try:
                await self._step()
            except EtcdError as exc:
                log.debug("hot standby: campaign: %s", exc)
            self._reconcile()

    async def _step(self) -> None:
        self._reconcile()
        await self._register()
        if not (self.view.fresh and self.lease.is_open()) or self._clock() < self._quiet_until:
            return
        lease = self.lease.id
        assert lease is not None
        now = self._clock()
        # lines no longer ours to master: silenced at once, deleted after the grace
        for line, holder in list(self.view.holders.items()):
            if holder.lease == lease and line not in self._lines:
                self._releasing.setdefault(line, now)
        if not self._releasing:
            give = self.policy.give_away(self._situation(now))
            if give is not None:
                log.info("hot standby: line %s given away to share the lines", give)
                self._releasing[give] = now
        self._reconcile()
        store = self._store
        for line, since in list(self._releasing.items()):
            if now - since >= RELEASE_GRACE and store == self._store:
                await self._release(line, lease)
        tried: set[str] = set()
        while self.lease.is_open() and self.lease.id == lease and store == self._store:
            situation = self._situation(self._clock())
            todo = [
                line
                for line in self.policy.campaign(situation)
                if line not in tried and line not in self._releasing
            ]
            if not todo:
                return
            line = todo[0]
            tried.add(line)
            fair = len(situation.mine) < share(len(situation.lines), situation.instances)
            if await self._campaign(line, lease) and not fair:
                self._orphans.add(line)
            self._reconcile()

    def _situation(self, now: float) -> Situation:
        return Situation(
            me=self.name,
            lines=self._lines,
            holders={line: h.master.name for line, h in self.view.holders.items()},
            live=set(self.view.instances),
            now=now,
            free_since=self.view.free_since,
            given=self._given,
            orphans=self._orphans,
            joined=self.view.joined,
        )

    async def _campaign(self, line: str, lease: int) -> bool:
        key, store = self.view.line_key(line), self._store
        won, answers, revision = await self.etcd.txn(
            [{"target": "CREATE", "key": b64(key), "create_revision": "0"}],
            [
                {
                    "request_put": {
                        "key": b64(key),
                        "value": b64(master_value(self.me.name, self.me.url)),
                        "lease": str(lease),
                    }
                }
            ],
            [{"request_range": {"key": b64(key)}}],
        )
        if store != self._store:  # answered by the store forgotten meanwhile
            return False
        if won:
            self.view.held_by(line, self.me, lease, revision)
            self._given.pop(line, None)
            return True
        for kv in range_kvs(answers[0]) if answers else []:
            self.view.apply_put(kv)
        return False

    async def _release(self, line: str, lease: int) -> None:
        key, store = b64(self.view.line_key(line)), self._store
        ours, _, revision = await self.etcd.txn(
            [{"target": "LEASE", "key": key, "lease": str(lease)}],
            [{"request_delete_range": {"key": key}}],
        )
        if store != self._store:  # answered by the store forgotten meanwhile
            return
        del self._releasing[line]
        if ours:
            self.view.freed(line, revision)
            self._given[line] = self._clock()

    async def _register(self) -> None:
        """This instance's key in the registry, on the registry's lease."""
        lease = self.registry.id
        if lease is None:
            return
        if lease == self._registered and (not self.view.fresh or self.name in self.view.instances):
            return
        key = self.view.instance_key(self.name)
        self.view.own_lease = lease  # before the put: its watch event may come first
        await self.etcd.put(key, master_value(self.me.name, self.me.url), lease)
        self._registered = lease
