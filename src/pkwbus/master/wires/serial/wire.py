"""FC and USS lines under the runner: one exchange at a time, run from the line's callbacks.

The runner's task awaits a run of exchanges: each result goes to the planner
in the line's callback, and the next exchange starts from the same callback
while the start pause runs, until the planner has nothing ready. Then the
runner may idle until the planner's next due time, or until a job comes in.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence

from pkwbus.link import Link
from pkwbus.master.planning.answers import ExchangeResult
from pkwbus.master.planning.health import HealthPolicy
from pkwbus.master.planning.plan import DriveSpec, Send
from pkwbus.master.planning.planner import Planner
from pkwbus.master.runner import LineRunner
from pkwbus.master.wires.serial.line import Line

__all__ = ["ExchangeWire"]


class ExchangeWire:
    """The :class:`~pkwbus.master.runner.Wire` of an FC or USS line."""

    def __init__(self, line: Line) -> None:
        self.line = line
        self._runner: LineRunner | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._run_over: asyncio.Future[None] | None = None  # one per run of exchanges
        self._send: Send | None = None
        self._sent_at = 0.0

    @property
    def link(self) -> Link:
        return self.line.link

    def planner_for(
        self,
        drives: Sequence[DriveSpec],
        retries: int,
        policy: HealthPolicy | None,
        poll_deadline: float | None,
    ) -> Planner:
        # Long enough for the retries and a lagging answer.
        deadline = poll_deadline or 4 * (retries + 1) * self.line.timeout
        return Planner(drives, poll_deadline=deadline, retries=retries, policy=policy)

    def attach(self, runner: LineRunner) -> None:
        self._runner = runner

    async def started(self) -> None:
        """Nothing to do before the first request: the line discards stray input itself."""

    async def carry(self) -> float | None:
        runner = self._runner
        assert runner is not None  # attached at the runner's construction
        loop = self._loop = asyncio.get_running_loop()
        action = runner.planner.next_action(loop.time())
        if not isinstance(action, Send):
            return action.until
        over = self._run_over = loop.create_future()
        self._start(action, loop)
        runner.flush()
        await over
        return None

    def lost(self) -> None:
        """The exchange in flight ends in the line's own loss callback."""

    async def close(self) -> None:
        await self.line.close()

    # ------------------------------------------------------------ internals

    def _start(self, send: Send, loop: asyncio.AbstractEventLoop) -> None:
        self._send = send
        self._sent_at = loop.time()
        self.line.start(send.address, send.telegram, self._exchanged)

    def _exchanged(self, result: ExchangeResult) -> None:
        """The line's callback: account for the result, start the next exchange."""
        over = self._run_over
        try:
            send, self._send = self._send, None
            loop, runner = self._loop, self._runner
            assert send is not None and loop is not None and runner is not None
            now = loop.time()
            runner.exchanged(send.drive, result, now - self._sent_at)
            planner = runner.planner
            planner.exchanged(send, result, now)
            if not runner.stopping and self.line.is_open:
                action = planner.next_action(now)
                if isinstance(action, Send):
                    self._start(action, loop)
                    runner.batch()  # while the start pause runs
                    return
            runner.flush()
        except Exception as exc:  # the runner's task reports it and reopens the port
            self._run_over = None
            if over is not None and not over.done():
                over.set_exception(exc)
            return
        self._run_over = None
        if over is not None and not over.done():
            over.set_result(None)
