"""Documents a line's master keeps in etcd, so that the next master finds them (issue
"hot standby", item 5: the drive-memory marks - log entries already told, settings
baselines, describe book).

Keys ``{prefix}/marks/{line}/{name}``, on no lease: they outlive a master. A mark is
written only in a transaction that checks that the line's key is on this instance's
lease: a master that lost the line (its lease expired, its process stopped and resumed)
never overwrites what the new master wrote. etcd takes values up to its request limit
(1.5 MiB by default, ``--max-request-bytes``).
"""

from __future__ import annotations

from typing import Protocol

from pkwbus.service.standby.etcd import Etcd, EtcdError, b64
from pkwbus.service.standby.view import View

__all__ = ["Holding", "Marks"]


class Holding(Protocol):
    """What the marks ask of the engine (:class:`~pkwbus.service.standby.engine.Standby`)."""

    etcd: Etcd
    view: View

    def held_lease(self, line: str) -> int | None: ...


class Marks:
    """The marks of the lines of one :class:`~pkwbus.service.standby.engine.Standby`."""

    def __init__(self, standby: Holding) -> None:
        self._standby = standby

    def key(self, line: str, name: str) -> str:
        if not name:
            raise ValueError("a mark needs a name")
        return f"{self._standby.view.prefix}/marks/{line}/{name}"

    async def get(self, line: str, name: str) -> bytes | None:
        """The mark's value, None when it was never written (read by any instance).

        Raises :class:`~pkwbus.service.standby.etcd.EtcdError` when etcd does not
        answer: "unknown" is not "none".
        """
        _, found = await self._standby.etcd.range(self.key(line, name))
        return found[0].value if found else None

    async def put(self, line: str, name: str, value: bytes) -> bool:
        """The mark written; False when this instance does not hold ``line`` (in etcd's
        eyes or its own) or etcd does not answer."""
        lease = self._standby.held_lease(line)
        if lease is None:
            return False
        line_key = b64(self._standby.view.line_key(line))
        try:
            done, _, _ = await self._standby.etcd.txn(
                [{"target": "LEASE", "key": line_key, "lease": str(lease)}],
                [{"request_put": {"key": b64(self.key(line, name)), "value": b64(value)}}],
            )
        except EtcdError:
            return False
        return done
