"""An etcd v3 client over etcd's own JSON gateway (etcd 3.4 and later: ``/v3/...``).

Keys and values travel base64-encoded, 64-bit numbers as JSON strings. Every request
goes to the endpoint that answered last; one that does not answer, answers 5xx, or says
it has no leader is left for the next, each of them tried once per request, each try
bounded by ``timeout``. :class:`EtcdUnavailable` says that none answered; a request
etcd refuses for itself is an :class:`EtcdRefused`. Requests ask for a member that has a
leader (gRPC metadata ``hasleader``), so a member cut off from the others answers no
stale read and keeps no watch that would never fire.

Watches (:meth:`Etcd.watch`) stream newline-delimited JSON on one HTTP request, with no
read timeout: they end when the member goes away or loses its leader.
"""

from __future__ import annotations

import base64
import json
import logging
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any, Final

import httpx

from pkwbus.errors import PkwbusError

__all__ = [
    "Etcd",
    "EtcdError",
    "EtcdRefused",
    "EtcdUnavailable",
    "Event",
    "KeyValue",
    "b64",
    "prefix_end",
    "range_kvs",
]

# gRPC codes that mean "ask another member" (UNAVAILABLE, DEADLINE_EXCEEDED,
# RESOURCE_EXHAUSTED: etcd's "too many requests"), and NOT_FOUND (a lease gone).
_RETRY_CODES: Final = frozenset({4, 8, 14})
NOT_FOUND: Final = 5
# etcd's own requirement that the member answering has a leader (rpctypes.MetadataRequireLeaderKey).
_HEADERS: Final = {"Grpc-Metadata-hasleader": "true", "Content-Type": "application/json"}


class _QuietRequests(logging.Filter):
    """httpx logs every request at INFO; a renewal every few seconds is no news."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not (
            record.levelno <= logging.INFO
            and str(record.msg).startswith("HTTP Request:")
            and any(str(a).endswith(_PATHS) for a in record.args or ())
        )


_PATHS: Final = tuple(
    f"/v3/{p}"
    for p in (
        "kv/range", "kv/put", "kv/txn", "kv/deleterange", "lease/grant", "lease/revoke",
        "lease/keepalive", "watch",
    )
)  # fmt: skip
_QUIET: Final = _QuietRequests()


class EtcdError(PkwbusError):
    """etcd could not do what was asked."""


class EtcdUnavailable(EtcdError):
    """No endpoint answered (down, unreachable, without a leader, or too slow)."""


class EtcdRefused(EtcdError):
    """An endpoint answered with an error of etcd's own (``code`` the gRPC code)."""

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code


def b64(data: bytes | str) -> str:
    raw = data.encode() if isinstance(data, str) else data
    return base64.b64encode(raw).decode("ascii")


def _unb64(text: str | None) -> bytes:
    return base64.b64decode(text) if text else b""


def prefix_end(prefix: bytes) -> bytes:
    """The end of the range of every key that starts with ``prefix`` (etcd's rule)."""
    end = bytearray(prefix)
    while end:
        if end[-1] < 0xFF:
            end[-1] += 1
            return bytes(end)
        end.pop()
    return b"\x00"


@dataclass(frozen=True)
class KeyValue:
    key: str
    value: bytes
    lease: int  # 0: none
    create_revision: int
    mod_revision: int

    @classmethod
    def of(cls, kv: dict[str, Any]) -> KeyValue:
        return cls(
            key=_unb64(kv.get("key")).decode("utf-8", "replace"),
            value=_unb64(kv.get("value")),
            lease=int(kv.get("lease", 0)),
            create_revision=int(kv.get("create_revision", 0)),
            mod_revision=int(kv.get("mod_revision", 0)),
        )


@dataclass(frozen=True)
class Event:
    """A change a watch saw: ``kv`` put, or (``deleted``) its key gone."""

    kv: KeyValue
    deleted: bool


class Etcd:
    """The cluster at ``endpoints``; each try of a request bounded by ``timeout`` seconds."""

    def __init__(
        self,
        endpoints: Sequence[str],
        timeout: float,
        clock: Callable[[], float],
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        if not endpoints:
            raise ValueError("etcd needs at least one endpoint")
        self.endpoints = [e.rstrip("/") for e in endpoints]
        self.timeout = timeout
        self.clock = clock
        self._current = 0
        logging.getLogger("httpx").addFilter(_QUIET)  # once: the same filter each time
        limits = httpx.Limits(max_connections=32, max_keepalive_connections=8)
        self._http = httpx.AsyncClient(
            timeout=httpx.Timeout(timeout), limits=limits, headers=_HEADERS, transport=transport
        )

    async def aclose(self) -> None:
        await self._http.aclose()

    # ------------------------------------------------------------------ requests

    async def call(self, path: str, body: dict[str, Any]) -> tuple[dict[str, Any], float]:
        """``body`` posted to ``path`` on each endpoint in turn, from the last that
        answered: the answer and the clock's time when its try was sent."""
        problems: list[str] = []
        content = json.dumps(body)
        for _ in range(len(self.endpoints)):
            endpoint = self.endpoints[self._current]
            sent = self.clock()
            try:
                response = await self._http.post(endpoint + path, content=content)
                answer = response.json()
            except (httpx.HTTPError, ValueError) as exc:
                problems.append(f"{endpoint}: {_why(exc)}")
                self._next()
                continue
            if not isinstance(answer, dict):
                problems.append(f"{endpoint}: answered {type(answer).__name__}, not an object")
                self._next()
                continue
            if "error" in answer or response.status_code >= 400:
                code = int(answer.get("code", 0) or 0)
                message = str(answer.get("message") or answer.get("error") or response.status_code)
                if code in _RETRY_CODES or response.status_code >= 500:
                    problems.append(f"{endpoint}: {message}")
                    self._next()
                    continue
                raise EtcdRefused(f"etcd at {endpoint}: {message}", code)
            return answer, sent
        raise EtcdUnavailable("etcd did not answer: " + "; ".join(problems))

    def _next(self) -> None:
        self._current = (self._current + 1) % len(self.endpoints)

    async def range(self, key: str, *, prefix: bool = False) -> tuple[int, list[KeyValue]]:
        """The revision of the answer, and the key's value (or every key under ``key``)."""
        body: dict[str, Any] = {"key": b64(key)}
        if prefix:
            body["range_end"] = b64(prefix_end(key.encode()))
        answer, _ = await self.call("/v3/kv/range", body)
        revision = int(answer.get("header", {}).get("revision", 0))
        return revision, [KeyValue.of(kv) for kv in answer.get("kvs", [])]

    async def put(self, key: str, value: bytes, lease: int = 0) -> None:
        body: dict[str, Any] = {"key": b64(key), "value": b64(value)}
        if lease:
            body["lease"] = str(lease)
        await self.call("/v3/kv/put", body)

    async def delete(self, key: str) -> int:
        """How many keys went."""
        answer, _ = await self.call("/v3/kv/deleterange", {"key": b64(key)})
        return int(answer.get("deleted", 0))

    async def txn(
        self,
        compare: list[dict[str, Any]],
        success: list[dict[str, Any]],
        failure: list[dict[str, Any]] | None = None,
    ) -> tuple[bool, list[dict[str, Any]], int]:
        """Whether every comparison held, the answers of the branch taken, and the
        revision of the store after it."""
        body = {"compare": compare, "success": success, "failure": failure or []}
        answer, _ = await self.call("/v3/kv/txn", body)
        revision = int(answer.get("header", {}).get("revision", 0))
        return bool(answer.get("succeeded", False)), list(answer.get("responses", [])), revision

    async def grant(self, ttl: float) -> tuple[int, int, float]:
        """A new lease of ``ttl`` seconds (rounded up): its id, the TTL etcd granted, and
        when the grant was sent."""
        answer, sent = await self.call("/v3/lease/grant", {"TTL": str(_whole(ttl))})
        return int(answer["ID"]), int(answer.get("TTL", 0)), sent

    async def keepalive(self, lease: int) -> tuple[int, float]:
        """The lease renewed: its TTL (0 or less: the lease is gone) and when the renewal
        was sent."""
        answer, sent = await self.call("/v3/lease/keepalive", {"ID": str(lease)})
        result = answer.get("result", answer)
        return int(result.get("TTL", 0)), sent

    async def revoke(self, lease: int) -> bool:
        """The lease revoked, its keys deleted; False when etcd knew it no longer."""
        try:
            await self.call("/v3/lease/revoke", {"ID": str(lease)})
        except EtcdRefused as exc:
            if exc.code == NOT_FOUND:
                return False
            raise
        return True

    # ------------------------------------------------------------------ watches

    @asynccontextmanager
    async def watch(
        self, prefixes: Sequence[str], start_revision: int
    ) -> AsyncIterator[AsyncIterator[list[Event]]]:
        """One stream watching every key under each of ``prefixes`` from ``start_revision``:
        yields the events of each answer. Opened on the endpoint that answered last
        (:class:`EtcdUnavailable` when it cannot be opened there: the caller's next call
        tries the next); ends, raising :class:`EtcdUnavailable`, when the stream breaks
        or etcd cancels it (a compacted revision, a member without leader)."""
        lines = []
        for prefix in prefixes:
            create = {
                "key": b64(prefix),
                "range_end": b64(prefix_end(prefix.encode())),
                "start_revision": str(start_revision),
            }
            lines.append(json.dumps({"create_request": create}))
        endpoint = self.endpoints[self._current]
        timeout = httpx.Timeout(self.timeout, read=None)
        request = self._http.build_request(
            "POST", endpoint + "/v3/watch", content="\n".join(lines) + "\n", timeout=timeout
        )
        try:
            response = await self._http.send(request, stream=True)
        except httpx.HTTPError as exc:
            self._next()
            raise EtcdUnavailable(f"etcd watch at {endpoint}: {_why(exc)}") from None
        try:
            if response.status_code != 200:
                self._next()
                raise EtcdUnavailable(f"etcd watch at {endpoint}: HTTP {response.status_code}")
            yield _events(response, endpoint)
        finally:
            await response.aclose()


async def _events(response: httpx.Response, endpoint: str) -> AsyncIterator[list[Event]]:
    try:
        async for line in response.aiter_lines():
            if not line.strip():
                continue
            answer = json.loads(line)
            if "error" in answer:
                raise EtcdUnavailable(f"etcd watch at {endpoint}: {answer.get('message')}")
            result = answer.get("result", {})
            if result.get("canceled") or result.get("compact_revision"):
                why = result.get("cancel_reason") or "compacted"
                raise EtcdUnavailable(f"etcd watch at {endpoint} ended: {why}")
            events = [
                Event(KeyValue.of(e.get("kv", {})), e.get("type") == "DELETE")
                for e in result.get("events", [])
            ]
            if events:
                yield events
    except (httpx.HTTPError, ValueError) as exc:
        raise EtcdUnavailable(f"etcd watch at {endpoint}: {_why(exc)}") from None
    raise EtcdUnavailable(f"etcd watch at {endpoint} ended")


def range_kvs(answer: dict[str, Any]) -> list[KeyValue]:
    """The keys of a range's answer within a transaction's answers."""
    found = answer.get("response_range", {})
    return [KeyValue.of(kv) for kv in found.get("kvs", [])] if isinstance(found, dict) else []


def _whole(seconds: float) -> int:
    whole = int(seconds)
    return whole if whole == seconds else whole + 1


def _why(exc: BaseException) -> str:
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
