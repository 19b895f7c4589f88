"""Writes from MQTT (``mqtt.writes: allow_list``): set topics through the one write path.

A client publishes ``{"value": 12.5, "store": "ram", "request_id": "r1"}`` on
``{prefix}/{line}/{drive}/set/{user}/{parameter}[/{index}]``. The set goes through
the write path the HTTP API uses (:mod:`pkwbus.service.writes.path`: the drive's
``writable`` list, the limits, the audit row before the wire, the job, the read-back),
its audit row's caller ``mqtt:{user}``; a drive's sets run one after the other, in
the order they came, each read back before the next is sent. The broker's ACL pins ``{user}`` to the
account that publishes (``topic write pkwbus/+/+/set/op1/#`` for ``op1``).

Never executed: a set published with the retain flag (the subscription keeps it,
MQTT 5's retain-as-published) and one whose MQTT 5 message expiry passed before it
would be sent; the subscription asks for retain handling 2, so the broker never hands
over a stored retained set, and no old command fires after a reconnect.

The result goes to the request's MQTT 5 response topic with its correlation data when
that topic is the publisher's own (``replies/{user}/...``: the ACL lets each operator read
only its own replies, and pkwbus writes under ``replies/#``), else to
``{prefix}/{line}/{drive}/result`` (QoS 1); another response topic (pkwbus's own, another
operator's) is never written to: ``{"request_id", "outcome", "audit_id",
...}`` with the audit log's outcome names (``ok``, ``refused``, ``invalid``,
``not_sent``, ``rejected``, ``mismatch``, ``unverified``, ``timeout``,
``cancelled``), the write's answer as the HTTP API gives it, or its ``error`` (kind
and message). Every set is read back; the verified value is published at once on its
value topic. A set that is refused (not ``writable``, a bad payload, an unknown drive
or parameter, retained, expired) sends nothing to the drive and is audited as the HTTP
API audits its refusals.

This module takes messages and hands back what to publish: the connection is the
caller's (:class:`Replies`). It raises nothing: every problem becomes a result.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Final

from pkwbus.errors import PkwbusError
from pkwbus.protocol import pkw
from pkwbus.protocol.values import ParameterRef
from pkwbus.service.mqtt.values import index_shown
from pkwbus.service.writes.checks import ApiError
from pkwbus.service.writes.path import WriteDone, WriteOrder, WritePath

__all__ = [
    "MAX_PAYLOAD",
    "MAX_PENDING",
    "MAX_REQUEST_ID",
    "MAX_USER",
    "Replies",
    "Reply",
    "SetMessage",
    "SetTopic",
    "SetTopics",
    "parse_set_topic",
]

log = logging.getLogger("pkwbus.service.mqtt")

MAX_PAYLOAD: Final = 4096  # bytes of a set's JSON, as the HTTP API's body
MAX_REQUEST_ID: Final = 128  # characters of a request_id echoed back
MAX_USER: Final = 64  # characters of the {user} segment kept in the audit row
MAX_PENDING: Final = 64  # sets under way at once; more are refused ("busy"), not queued
QOS_RESULT: Final = 1
REPLIES: Final = "replies/"  # under which each operator's own reply topics are


@dataclass(frozen=True, slots=True)
class SetMessage:
    """A message taken on a set topic, as the broker delivered it.

    ``expiry``: the MQTT 5 message expiry interval left when it arrived (seconds; None:
    it never expires); ``received``: when it arrived, on the set topics' clock (None: when
    they take it)."""

    topic: str
    payload: bytes
    retain: bool = False
    response_topic: str | None = None
    correlation_data: bytes | None = None
    expiry: float | None = None
    received: float | None = None


@dataclass(frozen=True, slots=True)
class Reply:
    """A message to publish: a result (QoS 1, not retained; with the request's
    correlation data when it goes to its response topic) or a verified value (QoS 0)."""

    topic: str
    payload: bytes
    qos: int
    correlation_data: bytes | None = None


Replies = Callable[[Reply], Awaitable[None]]


@dataclass(frozen=True, slots=True)
class SetTopic:
    line: str
    drive: str
    user: str
    parameter: str
    index: int | None


class _Refused(PkwbusError):
    """A set refused before the write path (internal: it becomes a result)."""

    def __init__(self, error: ApiError, outcome: str) -> None:
        super().__init__(str(error))
        self.error, self.outcome = error, outcome


def parse_set_topic(prefix: str, topic: str) -> SetTopic | None:
    """The parts of ``{prefix}/{line}/{drive}/set/{user}/{parameter}[/{index}]``; None
    for a topic of another shape (a parameter without a name, an index not 0-255)."""
    head = prefix + "/"
    if not topic.startswith(head):
        return None
    parts = topic[len(head) :].split("/")
    if len(parts) not in (5, 6) or parts[2] != "set" or not all(parts):
        return None
    index: int | None = None
    if len(parts) == 6:
        if not parts[5].isdigit() or not 0 <= int(parts[5]) <= 255:
            return None
        index = int(parts[5])
    return SetTopic(parts[0], parts[1], parts[3], parts[4], index)


class SetTopics:
    """The set topics of ``prefix``: each message taken becomes a write through ``path``
    and a result given to ``replies``; :attr:`topic_filter` is what to subscribe to."""

    def __init__(
        self,
        path: WritePath,
        prefix: str,
        replies: Replies,
        *,
        clock: Callable[[], float] = time.monotonic,
        wall: Callable[[], float] = time.time,
    ) -> None:
        self.path = path
        self.prefix = prefix
        self.replies = replies
        self.clock = clock
        self.wall = wall
        self.topic_filter = f"{prefix}/+/+/set/#"
        self._tasks: set[asyncio.Task[None]] = set()
        self._turns: dict[str, asyncio.Lock] = {}
        self._told: set[str] = set()  # users told once of a response topic not their own

    def take(self, message: SetMessage) -> None:
        """Handle ``message`` in a task of its own (the caller's loop is not held)."""
        if message.received is None:
            message = _stamped(message, self.clock())
        task = asyncio.get_running_loop().create_task(self.handle(message))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def settled(self) -> None:
        """Wait for the sets under way (a stop)."""
        while self._tasks:
            await asyncio.gather(*list(self._tasks), return_exceptions=True)

    async def handle(self, message: SetMessage) -> None:
        """Write what ``message`` asks, or refuse it, and publish the result."""
        topic = parse_set_topic(self.prefix, message.topic)
        if topic is None:
            return  # not a set topic of ours: the subscription's filter is wider
        request_id: Any = None
        try:
            body, request_id = _body(message.payload)
            if len(self._tasks) > MAX_PENDING:  # this one and MAX_PENDING others
                busy = ApiError(429, "busy", f"{MAX_PENDING} sets are under way: send it again")
                raise _Refused(busy, "not_sent")
            if message.retain:
                raise _Refused(ApiError(403, "retained", _RETAINED), "refused")
            self._check_line(topic)
            order = _order(body, topic.index)
            async with self._turn(topic.drive):
                if self._expired(message):
                    raise _Refused(ApiError(408, "expired", _EXPIRED), "not_sent")
                client = _client(topic.user)
                done = await self.path.write(topic.drive, topic.parameter, order, client)
        except _Refused as refused:
            await self._refused(topic, message, request_id, refused)
        except ApiError as exc:
            await self._answer(topic, message, _failed(request_id, exc))
        except Exception:  # a bug must not end the subscription: logged, answered
            log.exception("MQTT set on %s failed", message.topic)
            error = ApiError(500, "internal", "the set could not be handled: see the log")
            await self._answer(topic, message, _failed(request_id, error))
        else:
            await self._answer(topic, message, _done(request_id, done))
            await self._publish_value(topic, done)

    def _turn(self, drive: str) -> asyncio.Lock | contextlib.nullcontext[None]:
        """A drive's sets one after the other, in the order they came (each read back
        before the next is sent); an unknown drive's are refused at once."""
        if drive not in self.path.runtime.drives:
            return contextlib.nullcontext()
        return self._turns.setdefault(drive, asyncio.Lock())

    def _check_line(self, topic: SetTopic) -> None:
        entry = self.path.runtime.drives.get(topic.drive)
        if entry is not None and entry.line != topic.line:
            refusal = ApiError(
                404, "unknown_drive", f"no drive named {topic.drive!r} on line {topic.line!r}"
            )
            raise _Refused(refusal, "invalid")

    def _expired(self, message: SetMessage) -> bool:
        if message.expiry is None:
            return False
        received = self.clock() if message.received is None else message.received
        return self.clock() - received >= message.expiry

    async def _refused(
        self, topic: SetTopic, message: SetMessage, request_id: Any, refused: _Refused
    ) -> None:
        exc, client = refused.error, _client(topic.user)
        exc.outcome = refused.outcome
        exc.audit_incomplete = not await self.path.refuse(
            topic.drive, topic.parameter, topic.index, client, exc
        )
        await self._answer(topic, message, _failed(request_id, exc))

    async def _answer(self, topic: SetTopic, message: SetMessage, result: dict[str, Any]) -> None:
        payload = json.dumps(_finite(result), allow_nan=False, default=str).encode()
        response = message.response_topic
        if response and not _own_reply(response, topic.user):
            if topic.user not in self._told:
                self._told.add(topic.user)
                log.warning(
                    "MQTT: %s gave the response topic %r, not under %s%s/: answered on the"
                    " drive's result topic", _client(topic.user), response, REPLIES, topic.user,
                )  # fmt: skip
            response = None
        if response:
            reply = Reply(response, payload, QOS_RESULT, message.correlation_data)
        else:
            where = f"{self.prefix}/{topic.line}/{topic.drive}/result"
            reply = Reply(where, payload, QOS_RESULT)
        await self._send(reply)

    async def _publish_value(self, topic: SetTopic, done: WriteDone) -> None:
        body = done.body
        if body.get("verified") is not True:
            return
        where = self.value_topic(
            topic.line, topic.drive, body["parameter"], body["pnu"], body["index"]
        )
        value = {
            "v": _finite(body["value"]),
            "raw": body["raw"],
            "unit": body["unit"],
            "ts": round(self.wall() * 1000),
            "q": "good",
        }
        await self._send(Reply(where, json.dumps(value, allow_nan=False).encode(), 0))

    def value_topic(self, line: str, drive: str, parameter: str, pnu: int, index: int) -> str:
        """The value topic of ``drive``'s ``parameter`` (``pnu``) at ``index``, as its polled
        values have it (:func:`~pkwbus.service.mqtt.values.index_shown`)."""
        where = f"{self.prefix}/{line}/{drive}/value/{parameter}"
        runtime = self.path.runtime
        entry = runtime.drives.get(drive)
        array, polled = None, 0
        if entry is not None:
            polled = sum(1 for p in entry.polls if p.parameter == parameter)
            with contextlib.suppress(KeyError):  # a reload took the drive away meanwhile
                array = runtime.format_of(drive, ParameterRef(pnu, index, parameter)).array
        return f"{where}/{index}" if index_shown(array, polled, index) else where

    async def _send(self, reply: Reply) -> None:
        try:
            await self.replies(reply)
        except Exception as exc:  # the broker went away: the audit row holds the outcome
            log.warning("MQTT: could not publish to %s: %s", reply.topic, exc)


def _own_reply(topic: str, user: str) -> bool:
    """Whether ``topic`` is one of ``user``'s reply topics (and a topic one may publish to)."""
    return topic.startswith(f"{REPLIES}{user}/") and not any(c in topic for c in "+#\0")


_RETAINED = "a set published with the retain flag is never executed: publish it unretained"
_EXPIRED = "the set's message expiry passed before it could be sent: nothing was sent"


def _stamped(message: SetMessage, now: float) -> SetMessage:
    return SetMessage(
        message.topic,
        message.payload,
        message.retain,
        message.response_topic,
        message.correlation_data,
        message.expiry,
        now,
    )


def _client(user: str) -> str:
    return "mqtt:" + (user if len(user) <= MAX_USER else user[:MAX_USER] + "...")


def _invalid(problem: str) -> _Refused:
    return _Refused(ApiError(422, "invalid_request", problem), "invalid")


def _body(payload: bytes) -> tuple[dict[str, Any], Any]:
    """The set's JSON object and its request_id; refused when it is not one."""
    if len(payload) > MAX_PAYLOAD:
        raise _invalid(f"payload over {MAX_PAYLOAD} bytes")
    try:
        body = json.loads(payload, parse_constant=_no_constant)
    except (ValueError, UnicodeDecodeError) as exc:
        raise _invalid(f"the payload is not JSON: {str(exc)[:80]}") from None
    if not isinstance(body, dict):
        raise _invalid('the payload is not a JSON object: {"value": ..., "request_id": ...}')
    request_id = body.get("request_id")
    if request_id is not None and not (
        isinstance(request_id, str | int)
        and not isinstance(request_id, bool)
        and len(str(request_id)) <= MAX_REQUEST_ID
    ):
        raise _Refused(
            ApiError(
                422,
                "invalid_request",
                f"request_id: a string or a number of at most {MAX_REQUEST_ID} characters",
            ),
            "invalid",
        )
    return body, request_id


def _no_constant(name: str) -> None:
    raise ValueError(f"{name} is not a value")


def _order(body: dict[str, Any], index: int | None) -> WriteOrder:
    """The write a set asks for: every set is read back."""
    unknown = sorted(set(body) - {"value", "store", "request_id"})
    if unknown:
        raise _invalid(f"unknown fields: {', '.join(k[:40] for k in unknown[:5])}")
    if "value" not in body:
        raise _invalid("value: missing")
    value = body["value"]
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise _invalid("value: a number, or a string for a text parameter")
    if isinstance(value, float) and not math.isfinite(value):
        raise _invalid("value: not a finite number")
    try:
        store = pkw.Store(body.get("store", "ram"))
    except ValueError:
        raise _invalid("store: ram or eeprom") from None
    return WriteOrder(value, index, store, verify=True)


def _done(request_id: Any, done: WriteDone) -> dict[str, Any]:
    body = {k: v for k, v in done.body.items() if k != "dry_run"}
    return {"request_id": request_id, "outcome": done.outcome, **body}


def _failed(request_id: Any, exc: ApiError) -> dict[str, Any]:
    return {
        "request_id": request_id,
        "outcome": exc.outcome or "not_sent",
        "audit_id": exc.audit_id,
        **exc.body(),
    }


def _finite(value: Any) -> Any:
    """``value`` with every number that is not finite as None (JSON has no such number)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value
