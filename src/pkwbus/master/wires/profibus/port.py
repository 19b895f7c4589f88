"""One PROFIBUS DP line: the port, 8E1, the bus timing, one request and its answer at a time.

The same port layer as FC and USS lines (:class:`pkwbus.link.Link`: device
paths, ``socket://`` and ``rfc2217://`` URLs, echo suppression). Before every
request the line stays idle for TID1 = 37 bit times (which covers TSYN = 33,
EN 50170 vol. 2 part 4, section 4.4); an answer must start within the slot
time. The answer is a frame from the station asked, to this master, or a
short acknowledge: another slave's answer that missed its own slot time is
not taken for it. The deframer is told of the gap at every request
(``flush``), so a short acknowledge after noise is found. Before going active the master
listens for the token-lost time; a token or a request from another address
means another master runs the line, and pkwbus never shares a line with one
(:class:`ForeignMaster`); what was heard is forgotten when the port fails
(given up or lost), and heard afresh when it opens again. The port of a line's
master (``clear_on_close``) sends Global_Control Clear to its slaves before it
closes.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

from pkwbus.link import Fence, Link, LinkState, PortError, PortSettings
from pkwbus.master.bus import Done, LineRefused
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp.services import global_control_clear
from pkwbus.protocol.profibus.dp.slave import Answer, Garbled, NoAnswer
from pkwbus.protocol.profibus.fdl import DataFrame, Frame, FramingError, ShortAck, Skipped, Token
from pkwbus.protocol.profibus.fdl import timing as dp_timing

__all__ = ["FdlPort", "ForeignMaster", "TraceHook", "describe_frame"]

TraceHook = Callable[[str, str], None]  # direction ("tx"/"rx"), the decoded frame


class ForeignMaster(LineRefused):
    """Another master is active on the line: pkwbus does not go active."""


def _sd(frame: DataFrame) -> str:
    if frame.body_length == 3:
        return "SD1"
    if frame.dsap is None and frame.ssap is None and len(frame.data) == fdl.SD3_DATA:
        return "SD3"
    return "SD2"


def describe_frame(event: Frame | FramingError) -> str:
    """One line for a frame: ``SD2 da=8 sa=2 fc=0x5d dsap=61 ssap=62 data=b8 1e``."""
    if isinstance(event, ShortAck):
        return "SC"
    if isinstance(event, Token):
        return f"SD4 da={event.da} sa={event.sa}"
    if isinstance(event, DataFrame):
        text = f"{_sd(event)} da={event.da} sa={event.sa} fc={event.fc:#04x}"
        if event.dsap is not None:
            text += f" dsap={event.dsap}"
        if event.ssap is not None:
            text += f" ssap={event.ssap}"
        if event.data:
            text += f" data={event.data.hex(' ')}"
        return text
    if isinstance(event, FramingError):
        return f"! {event.describe()}"
    return type(event).__name__


def _foreign(event: Frame, master: int) -> str | None:
    """What makes ``event`` another master's traffic, or None."""
    if isinstance(event, Token):
        return f"a token from station {event.sa} to {event.da}"
    if isinstance(event, DataFrame) and event.control.is_request and event.sa != master:
        return f"a request from station {event.sa} to {event.da}"
    return None


class FdlPort:
    """A DP line: one port, one request at a time, answers within the slot time."""

    def __init__(
        self,
        settings: PortSettings,
        master: int,
        *,
        slot_time: float | None = None,
        trace: TraceHook | None = None,
        listen: float | None = None,
        fence: Fence | None = None,
        clear_on_close: bool = False,
    ) -> None:
        baud = settings.baudrate
        self.master = master
        self.slot_time = slot_time if slot_time is not None else dp_timing.default_slot_time(baud)
        if self.slot_time <= 0:
            raise ValueError(f"slot time {self.slot_time} s is not positive")
        # The idle time before each request (TID1 >= TSYN), the character always 8E1.
        pause = dp_timing.bits(max(dp_timing.TID1_BITS, dp_timing.TSYN_BITS), baud)
        self.settings = PortSettings(
            settings.url,
            baudrate=baud,
            parity="E",
            stopbits=1,
            pause=pause,
            echo=settings.echo,
            reopen_initial=settings.reopen_initial,
            reopen_cap=settings.reopen_cap,
            low_latency=settings.low_latency,
            rs485=settings.rs485,
        )
        self.trace = trace
        self.listen_for = listen  # how long to listen before going active (None: TTO)
        # Global_Control Clear to every slave before closing: a master that leaves the line
        # clears its slaves (the live list's port parametrised none: it closes so).
        self.clear_on_close = clear_on_close
        self.link = Link(self.settings, receiver=self._on_data, on_lost=self._on_lost, fence=fence)
        self.link.reconnect.add_listener(self._on_port)
        self.foreign: str | None = None  # another master heard, and how
        self.requests = 0
        self.sent_at = 0.0  # loop time the latest request was written (its idle time over)
        self._deframer = fdl.Deframer()
        self._lock = asyncio.Lock()
        self._waiter: asyncio.Future[Answer] | None = None
        self._asked = 0  # the station the request out was sent to
        self._garbled: str | None = None
        self._deadline = 0.0
        self._timer: asyncio.TimerHandle | None = None
        self._listening = False

    @property
    def is_open(self) -> bool:
        return self.link.is_open

    async def open(self) -> None:
        await self.link.open()

    async def close(self) -> None:
        """Close the port; first Global_Control Clear to every slave where the line's master
        leaves it (``clear_on_close``), while the port is there and nobody else runs it."""
        with contextlib.suppress(PortError, ForeignMaster):
            if self.clear_on_close and self.is_open and self.foreign is None and self.requests:
                await self.broadcast(global_control_clear(self.master))
        await self.link.close()

    async def started(self) -> None:
        """The port just opened: listen for other masters before the first request
        (:class:`ForeignMaster` when one is heard)."""
        await self.listen(self.listen_for)

    def start(self, request: DataFrame, done: Done[Answer]) -> None:
        """The runner's request: ``done`` gets its answer, or the exception that ended it."""
        task = asyncio.get_running_loop().create_task(self.exchange(request))

        def finished(task: asyncio.Task[Answer]) -> None:
            if task.cancelled():
                return
            exc = task.exception()
            done(exc if exc is not None else task.result())

        task.add_done_callback(finished)

    def token_lost_time(self) -> float:
        return dp_timing.token_lost_time(self.slot_time, self.master)

    async def listen(self, seconds: float | None = None) -> None:
        """Listen without sending (the token-lost time by default); :class:`ForeignMaster`
        when another master is heard."""
        wait = self.token_lost_time() if seconds is None else seconds
        self._deframer.reset()
        self._listening = True
        try:
            await asyncio.sleep(wait)
            self._handle(self._deframer.flush())
        finally:
            self._listening = False
        if self.foreign is not None:
            raise ForeignMaster(self._refusal())

    def _refusal(self) -> str:
        return (
            f"another master is active on {self.settings.url} ({self.foreign});"
            " pkwbus does not share a PROFIBUS line with another master: nothing was sent"
        )

    async def exchange(self, frame: DataFrame) -> Answer:
        """Send a request and wait for its answer: a frame, :class:`NoAnswer` or
        :class:`Garbled`. :class:`PortError` when the port is gone, :class:`ForeignMaster`
        when another master is heard."""
        async with self._lock:
            return await self._exchange(frame)

    async def _exchange(self, frame: DataFrame) -> Answer:
        if self.foreign is not None:
            raise ForeignMaster(self._refusal())
        loop = asyncio.get_running_loop()
        raw = fdl.encode(frame)
        self._handle(self._deframer.flush())  # a gap: what is buffered is complete or noise
        self._deframer.reset()
        self._garbled = None
        waiter: asyncio.Future[Answer] = loop.create_future()
        self._waiter = waiter
        self._asked = frame.da
        try:
            await self.link.send(raw)
            self.sent_at = loop.time()
            self.requests += 1
            if self.trace:
                self.trace("tx", describe_frame(frame))
            self._deadline = loop.time() + self.settings.wire_time(len(raw)) + self.slot_time
            self._arm(loop)
            return await waiter
        finally:
            self._waiter = None
            if waiter.done() and not waiter.cancelled():
                waiter.exception()  # a loss while the request went out: raised there, not here
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None

    async def broadcast(self, frame: DataFrame) -> None:
        """Send a frame nobody answers (SDN), then wait TID2 = max TSDR."""
        async with self._lock:
            raw = fdl.encode(frame)
            self._deframer.reset()
            await self.link.send(raw)
            self.requests += 1
            if self.trace:
                self.trace("tx", describe_frame(frame))
            baud = self.settings.baudrate
            tid2 = dp_timing.bits(dp_timing.MAX_TSDR_BITS, baud)
            await asyncio.sleep(self.settings.wire_time(len(raw)) + tid2)

    # ------------------------------------------------------------ internals

    def _arm(self, loop: asyncio.AbstractEventLoop) -> None:
        if self._timer is not None:
            self._timer.cancel()
        self._timer = loop.call_at(self._deadline, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        waiter = self._waiter
        if waiter is None or waiter.done():
            return
        loop = asyncio.get_running_loop()
        if self._deadline - loop.time() > 1e-4:
            self._arm(loop)
            return
        self._handle(self._deframer.flush())
        if not waiter.done():
            waiter.set_result(Garbled(self._garbled) if self._garbled is not None else NoAnswer())

    def _on_data(self, data: bytes) -> None:
        if self._waiter is None and not self._listening:
            self._handle(self._deframer.feed(data))  # stray traffic: watched for other masters
            return
        self._handle(self._deframer.feed(data))
        waiter = self._waiter
        if waiter is not None and not waiter.done() and self._deframer.buffered:
            # An answer under way: give its remaining bytes a slot time after each chunk.
            loop = asyncio.get_running_loop()
            self._deadline = max(self._deadline, loop.time() + self.slot_time)

    def _handle(self, events: list[fdl.DeframerEvent]) -> None:
        waiter = self._waiter
        for event in events:
            if self.trace:
                self.trace("rx", describe_frame(event))
            if isinstance(event, FramingError):
                if not isinstance(event, Skipped):
                    self._garbled = event.describe()
                continue
            why = _foreign(event, self.master)
            if why is not None:
                self.foreign = self.foreign or why
                if waiter is not None and not waiter.done():
                    waiter.set_exception(ForeignMaster(self._refusal()))
                continue
            if waiter is not None and not waiter.done() and self._answers(event):
                self.link.usable()  # a station answered: the port is usable
                waiter.set_result(event)
        if (
            waiter is not None
            and not waiter.done()
            and self._garbled is not None
            and not self._deframer.buffered
        ):
            waiter.set_result(Garbled(self._garbled))

    def _answers(self, event: Frame) -> bool:
        """Whether ``event`` can be the answer to the request out: a data frame from the
        station asked, to this master (a late answer of another slave is not), or the
        short acknowledge, which names no station."""
        if isinstance(event, DataFrame):
            return event.sa == self._asked and event.da == self.master
        return True

    def _on_port(self, state: LinkState, error: str | None) -> None:
        """The port failed (given up, lost, or not opened): another master heard is
        forgotten, and listened for afresh once it opens again."""
        if state is LinkState.FAILED:
            self.foreign = None

    def _on_lost(self, reason: str) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_exception(PortError(reason))
