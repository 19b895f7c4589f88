"""One connection's answering session: requests in, answers out in their turn, with the
timing of an RS-485 line.

Timing of one exchange, as the master sees it on an RS-485 line:

    first request byte ── request on the wire ── response delay ── answer on the wire ──┤

The session takes the arrival of the request's first byte as the start, adds
the request's wire time (``len * 11 / baud``, when wire timing is on) and the
response delay: the answer starts there, and each piece of it is written once
its last byte has crossed the line, so the master never gets a byte earlier
than a real line would deliver it, and sees a long answer arrive as it is sent.
Requests are answered one at a time, in order (half duplex). A late answer
(fault) is written later without holding the line.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from pkwbus.sim.config import SimTiming
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.serving.stats import SimStats

__all__ = ["STREAM_PIECE", "Answerer", "RequestDeframer", "Session", "Write"]

Write = Callable[[bytes], None]
# With wire timing, an answer longer than this on the line is delivered in pieces of about
# this much wire time, as a UART passes it on (the reader sees it arrive, and waits on).
STREAM_PIECE = 0.002  # seconds


class Answerer(Protocol):
    """What an end needs of the line it serves (a :class:`pkwbus.sim.Simulator`)."""

    @property
    def stats(self) -> SimStats: ...

    @property
    def timing(self) -> SimTiming: ...

    def deframer(self) -> RequestDeframer: ...

    def is_request(self, event: object) -> bool:
        """Whether a deframer event is a request to answer (else a framing error)."""
        ...

    def request_size(self, event: object) -> int:
        """Bytes the request took on the wire."""
        ...

    def answer(self, request: Any, now: float | None = None) -> Answer | None: ...


class RequestDeframer(Protocol):
    """A streaming deframer: FC/USS telegrams, or PROFIBUS FDL frames."""

    @property
    def buffered(self) -> int: ...

    def feed(self, data: bytes) -> Sequence[object]: ...


class Session:
    """One conversation on an end: deframes requests and answers them with timing."""

    def __init__(self, sim: Answerer, write: Write) -> None:
        self.sim = sim
        self._write = write
        self._deframer = sim.deframer()
        self._queue: asyncio.Queue[tuple[object, float]] = asyncio.Queue()
        self._loop = asyncio.get_running_loop()
        self._started = 0.0
        self._late: set[asyncio.TimerHandle] = set()  # late answers still to send
        self._task = self._loop.create_task(self._answer_in_turn())

    def feed(self, chunk: bytes) -> None:
        now = self._loop.time()
        if not self._deframer.buffered:
            self._started = now
        for event in self._deframer.feed(chunk):
            if self.sim.is_request(event):
                self._queue.put_nowait((event, self._started))
                self._started = now
            else:
                self.sim.stats.count("bad_requests")

    async def _answer_in_turn(self) -> None:
        timing = self.sim.timing
        while True:
            request, started = await self._queue.get()
            answer = self.sim.answer(request)
            if answer is None:
                continue
            begins = started + timing.wire_seconds(self.sim.request_size(request))
            begins += timing.response_delay  # the answer's first character starts now
            delay = begins + timing.wire_seconds(len(answer.data)) - self._loop.time()
            if answer.late:
                self._send_later(max(delay, 0.0) + answer.late, answer)
                continue
            await self._stream(answer, begins)

    async def _stream(self, answer: Answer, begins: float) -> None:
        """The answer as a line delivers it: with wire timing, each piece of it once its
        last character has crossed the line (a long answer arrives as it is sent, not
        in one piece after its whole wire time); else at once."""
        timing = self.sim.timing
        data = answer.data
        size = len(data)
        if timing.wire_seconds(size) > STREAM_PIECE:
            per = max(1, int(STREAM_PIECE / timing.wire_seconds(1)))
            for end in range(per, size, per):
                delay = begins + timing.wire_seconds(end) - self._loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
                self._send(Answer(data[end - per : end]))
            data = data[(size - 1) // per * per :]
        delay = begins + timing.wire_seconds(size) - self._loop.time()
        if delay > 0:
            await asyncio.sleep(delay)
        self._send(Answer(data))

    def _send_later(self, delay: float, answer: Answer) -> None:
        def send() -> None:
            self._late.discard(handle)
            self._send(answer)

        handle = self._loop.call_later(delay, send)
        self._late.add(handle)

    def _send(self, answer: Answer) -> None:
        try:
            self._write(answer.data)
        except OSError:
            self.sim.stats.count("unsent")

    async def close(self) -> None:
        """Stop answering; late answers not yet sent never are (the end they were for
        is gone, and its descriptor's number may be another's by then)."""
        for handle in self._late:
            handle.cancel()
        self._late.clear()
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task
