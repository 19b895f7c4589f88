"""The status page of an instance in hot standby, in a real headless browser (Debian's
chromium, driven by Playwright): a line mastered here shows its port; a line another
instance masters says which, linking to its page; a line nobody masters is closed; the
line mastered here whose gateway is gone is closed in red, not "mastered by" itself. Skipped,
saying why, without chromium or Playwright (deploy/browser-setup installs them)."""

from __future__ import annotations

import asyncio
import shutil
import socket
import threading
from pathlib import Path
from typing import Any

import pytest
import uvicorn

from tests.service.standby_service.fakes import FakeEngine, Master, service, until

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]  # fmt: skip


class Served:
    """The standby service of :func:`service` in a loop of its own thread, on ``url``."""

    def __init__(self) -> None:
        self.ready = threading.Event()
        self.stop = threading.Event()
        self.url = ""
        self.engine: FakeEngine | None = None
        self.gateway: Any = None  # l1's simulated gateway
        self.loop: asyncio.AbstractEventLoop | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="standby", daemon=True)

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # reported to the test
            self.error = exc
            self.ready.set()

    async def _main(self) -> None:
        async with service() as svc:
            svc.engine.grant("l1")
            svc.engine.masters["l2"] = Master("hall-b", "http://hall-b.example:9725/")
            await until(lambda: bool(svc.runtime.snapshot.lines.get("l1")))
            self.engine, self.loop = svc.engine, asyncio.get_running_loop()
            self.gateway = svc.ends["l1"]
            sock = socket.socket()
            sock.bind(("127.0.0.1", 0))
            host, port = sock.getsockname()
            config = uvicorn.Config(svc.client._transport.app,  # type: ignore[attr-defined]
                                    log_config=None, access_log=False, lifespan="off",
                                    log_level="error")  # fmt: skip
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

    def call(self, what: Any) -> None:
        assert self.loop is not None
        self.loop.call_soon_threadsafe(what)


def test_a_standby_names_the_master_of_each_line_with_a_link(tmp_path: Path) -> None:
    sync_api = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no chromium at {CHROMIUM} (deploy/browser-setup installs it)")
    expect = sync_api.expect
    served = Served()
    served.thread.start()
    assert served.ready.wait(60), "the service did not start"
    if served.error is not None:
        raise served.error
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            try:
                page = browser.new_page(viewport={"width": 1400, "height": 900})

                def only_here(route: Any) -> None:  # no internet: anything else is refused
                    here = route.request.url.startswith(served.url)
                    route.continue_() if here else route.abort()

                page.route("**/*", only_here)
                page.goto(served.url + "/")
                here = page.locator('#lines [data-line="l1"] .port')
                there = page.locator('#lines [data-line="l2"] .port')
                expect(here).to_have_text("open", timeout=20_000)
                expect(there).to_have_text("mastered by hall-b")
                link = there.locator("a")
                expect(link).to_have_attribute("href", "http://hall-b.example:9725/")
                expect(link).to_have_text("hall-b")
                expect(page.locator("#lines tfoot")).to_contain_text(
                    "1 of 1 open, 1 mastered elsewhere"
                )
                page.screenshot(path=str(tmp_path / "standby.png"))
                # Nobody masters l2 now: closed, no link.
                engine = served.engine
                assert engine is not None
                served.call(lambda: engine.masters.pop("l2"))
                expect(there).to_have_text("closed", timeout=20_000)
                expect(there.locator("a")).to_have_count(0)
                expect(page.locator("#lines tfoot")).to_contain_text("1 of 2 open")
                # l1's gateway goes away: mastered here, its port is closed, in red.
                gateway = served.gateway
                assert served.loop is not None and gateway is not None
                asyncio.run_coroutine_threadsafe(gateway.close(), served.loop).result(30)
                expect(here).to_have_text("closed", timeout=20_000)
                expect(here).to_have_class("port bad")
                expect(page.locator("#lines tfoot")).to_contain_text("0 of 2 open")
            finally:
                browser.close()
    finally:
        served.stop.set()
        served.thread.join(30)
