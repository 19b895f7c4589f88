"""The service of :func:`tests.service.http.conftest.service` in an event loop of its own thread,
served by uvicorn on a loopback port, for clients that are not asyncio (a browser,
schemathesis over requests)."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import uvicorn

from pkwbus.master.reading import Reading
from pkwbus.service.http.api import create_app
from tests.service.http.conftest import service


class ServedInThread:
    """Started, served on ``url``, stopped; ``svc``, ``app`` and ``loop`` once ready."""

    def __init__(self, tmp_path: Path, token: str, drives: dict[str, Any]) -> None:
        self.tmp_path = tmp_path
        self.token = token
        self.drives = drives
        self.ready = threading.Event()
        self.stop = threading.Event()
        self.url = ""
        self.svc: Any = None
        self.app: Any = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="service", daemon=True)

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # reported to the test
            self.error = exc
            self.ready.set()

    async def _main(self) -> None:
        async with service(self.tmp_path, **self.drives) as svc:
            self.svc, self.loop = svc, asyncio.get_running_loop()
            self.app = create_app(svc.runtime, audit=svc.audit, write_token=self.token)
            sock = socket.socket()
            sock.bind(("127.0.0.1", 0))
            host, port = sock.getsockname()
            config = uvicorn.Config(
                self.app, log_config=None, access_log=False, lifespan="off", log_level="error"
            )
            server = uvicorn.Server(config)
            task = asyncio.create_task(server.serve(sockets=[sock]))
            while not server.started:
                await asyncio.sleep(0.01)
            self.url = f"http://{host}:{port}"
            self.ready.set()
            while not self.stop.is_set():
                await asyncio.sleep(0.05)
            server.should_exit = True
            await task

    def set_value(self, address: int, pnu: int, raw: int) -> None:
        """Change a simulated drive's parameter, in the service's own loop."""
        assert self.loop is not None
        drive = self.svc.sim.drives[address]
        self.loop.call_soon_threadsafe(drive.set_value, pnu, raw)

    def keypad(self, address: int, pnu: int, raw: int) -> None:
        """A person at a simulated drive's keypad sets ``pnu`` to ``raw`` (no telegram), in
        the service's own loop; its ValueError comes back here."""
        assert self.loop is not None

        async def set_it() -> None:
            self.svc.sim.keypad(address, pnu, raw)

        asyncio.run_coroutine_threadsafe(set_it(), self.loop).result(timeout=30)

    def history(self, drive: str, parameter: str, values: list[float]) -> None:
        """Give a value the trend it would have after a quarter of an hour: ``values``, one
        a trend point (15 s) apart, the last one a point before now."""
        assert self.loop is not None
        trends = self.svc.runtime.trends

        async def landed() -> None:
            now = time.time()
            for k, value in enumerate(reversed(values), 1):
                trends.landed((drive, parameter, 0), Reading(value, None, now - k * trends.step))

        asyncio.run_coroutine_threadsafe(landed(), self.loop).result(timeout=30)

    def trip(self, address: int, code: int, bit: int) -> None:
        """Trip a simulated drive: alarm ``code`` in its log, ``bit`` in its alarm word."""
        assert self.loop is not None
        self.loop.call_soon_threadsafe(self.svc.sim.drives[address].model.trip, code, bit)


@contextlib.contextmanager
def served_in_thread(tmp_path: Path, token: str, **drives: Any) -> Iterator[ServedInThread]:
    """``drives``: the ``fc``/``uss`` lists of :func:`tests.service.http.conftest.service`."""
    served = ServedInThread(tmp_path, token, drives)
    served.thread.start()
    assert served.ready.wait(60), "the service did not start"
    if served.error is not None:
        raise served.error
    try:
        yield served
    finally:
        served.stop.set()
        served.thread.join(30)
