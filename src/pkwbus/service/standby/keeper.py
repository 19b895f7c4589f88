"""A lease kept alive in etcd: granted, renewed every lease / 3, its fence on our clock.

The keeper tells its owner (``changed``) whenever something it knows changed: a lease
granted, a renewal failed or came back, the fence closed, the lease found gone (a
renewal answered with no TTL left: etcd forgot it). A lease whose fence closed while
etcd was away is renewed again when etcd answers: if etcd still has it, its keys never
left, and the fence opens again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from typing import Final

from pkwbus.service.standby.etcd import Etcd, EtcdError, EtcdRefused
from pkwbus.service.standby.fence import LeaseClock, renew_every, retry_every
from pkwbus.waiting import wait_event

__all__ = ["LeaseKeeper"]

log = logging.getLogger("pkwbus.service.standby")

# How soon a grant is tried again after etcd did not answer it.
_GRANT_RETRY: Final = 1.0


class LeaseKeeper:
    """Keeps one lease of ``lease`` seconds (``what`` names it in the log)."""

    def __init__(
        self,
        etcd: Etcd,
        lease: float,
        what: str,
        changed: Callable[[], None],
        failed: Callable[[EtcdError], None],
        answered: Callable[[], None],
    ) -> None:
        self.etcd = etcd
        self.lease = lease
        self.what = what
        self._changed = changed
        self._failed = failed
        self._answered = answered
        self.id: int | None = None
        self.fence = LeaseClock(lease, etcd.clock)
        self._last_sent = 0.0
        self._was_open = False
        self._wake = asyncio.Event()

    @property
    def clock(self) -> Callable[[], float]:
        return self.etcd.clock

    def is_open(self) -> bool:
        return self.id is not None and self.fence.is_open()

    def forget(self) -> None:
        """The lease is no longer used (revoked, gone, given up): its fence closes at once,
        and a new one is granted."""
        self.fence.close()
        self.id = None
        self.fence = LeaseClock(self.lease, self.clock)
        self._was_open = False
        self._wake.set()

    async def run(self) -> None:
        """Grant, renew, tell; until cancelled."""
        while True:
            if self.id is None:
                await self._grant()
                continue
            now = self.clock()
            due = self._last_sent + renew_every(self.lease)
            if self.fence.is_open() and now < due:
                await self._sleep(min(due, self.fence.open_until()) - now)
                self._note_closing()
                continue
            await self._renew()

    async def _grant(self) -> None:
        try:
            lease, ttl, sent = await self.etcd.grant(self.lease)
        except EtcdError as exc:
            self._failed(exc)
            await self._sleep(_GRANT_RETRY)
            return
        self._answered()
        if ttl <= 0:
            return
        self.id = lease
        self.fence = LeaseClock(self.lease, self.clock)
        self.fence.renewed(sent, ttl)
        self._last_sent = sent
        self._was_open = True
        log.debug("hot standby: %s lease %x granted (%d s)", self.what, lease, ttl)
        self._changed()

    async def _renew(self) -> None:
        lease = self.id
        assert lease is not None
        try:
            ttl, sent = await self.etcd.keepalive(lease)
        except EtcdError as exc:
            self._failed(exc)
            self._note_closing()
            left = self.fence.left()
            retry = retry_every(self.lease)
            await self._sleep(min(retry, left) if left > 0 else retry)
            self._note_closing()
            return
        if self.id != lease:  # forgotten meanwhile
            return
        self._answered()
        if ttl <= 0:
            log.warning(
                "hot standby: etcd no longer has this instance's %s lease (expired): its"
                " keys are gone",
                self.what,
            )
            self.forget()
            self._changed()
            return
        self.fence.renewed(sent, ttl)
        self._last_sent = sent
        if not self._was_open:
            self._was_open = True
            self._changed()

    def _note_closing(self) -> None:
        """Tell once when the fence has closed."""
        if self._was_open and not self.fence.is_open():
            self._was_open = False
            self._changed()

    async def _sleep(self, seconds: float) -> None:
        self._wake.clear()
        await wait_event(self._wake, seconds)

    async def revoke(self) -> None:
        """The lease revoked (its keys deleted at once), best effort; forgotten here."""
        lease = self.id
        self.forget()
        if lease is None:
            return
        with contextlib.suppress(EtcdRefused):
            await self.etcd.revoke(lease)
