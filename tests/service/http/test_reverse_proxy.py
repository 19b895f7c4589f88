"""The status page behind a reverse proxy at a path prefix (an ingress at
``https://plant/pkwbus/``): `pkwbus run` as a process, nginx in front of it at
``/pkwbus/``, and the page in Chromium showing the drives, with its assets, the API docs
and the metrics reached through the prefix. .ci/run installs nginx and chromium
(deploy/browser-setup); without them the test is skipped with the reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from pkwbus.sim import SimTiming, Simulator
from tests.reliability.service import start_run
from tests.service.http.conftest import line_yaml
from tests.service.http.test_status_page import ARGS, CHROMIUM

NGINX = shutil.which("nginx") or "/usr/sbin/nginx"
PREFIX = "/pkwbus/"
DRIVES = [
    {"name": f"fan{a}", "address": a, "catalog": "danfoss-fc",
     "poll": [("3-41", "100ms"), ("16-13", "200ms")]}
    for a in (1, 2)
]  # fmt: skip


def nginx_conf(folder: Path, port: int, upstream: int) -> str:
    """A proxy that strips the prefix, as an ingress does; temporary files in ``folder``."""
    return f"""
worker_processes 1;
error_log {folder}/error.log;
pid {folder}/nginx.pid;
events {{ worker_connections 64; }}
http {{
    access_log {folder}/access.log;
    client_body_temp_path {folder}/body;
    proxy_temp_path {folder}/proxy;
    fastcgi_temp_path {folder}/fastcgi;
    uwsgi_temp_path {folder}/uwsgi;
    scgi_temp_path {folder}/scgi;
    server {{
        listen 127.0.0.1:{port};
        location {PREFIX} {{
            proxy_pass http://127.0.0.1:{upstream}/;
            proxy_buffering off;
        }}
    }}
}}
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def nginx(folder: Path, upstream: int) -> Iterator[int]:
    """nginx in the foreground on a free loopback port (tried again where another process
    took the port between its pick and nginx's bind)."""
    for _ in range(5):
        port = free_port()
        conf = folder / "nginx.conf"
        conf.write_text(nginx_conf(folder, port, upstream))
        proc = subprocess.Popen(
            [NGINX, "-p", str(folder), "-c", str(conf), "-g", "daemon off;"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )  # fmt: skip
        end = time.monotonic() + 15
        while proc.poll() is None and time.monotonic() < end:
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
                break
            time.sleep(0.05)
        if proc.poll() is None:
            try:
                yield port
            finally:
                proc.terminate()
                proc.wait(10)
            return
        err = proc.stderr.read().decode() if proc.stderr else ""
        if "Address already in use" not in err:
            raise AssertionError(f"nginx did not start: {err}")
    raise AssertionError("nginx found no free port")


class Background:
    """An event loop in a thread of its own: the simulator's line and the `pkwbus run`
    process are served there while the browser is driven from the test's thread."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()

    def call(self, coro: Any, timeout: float = 60.0) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)


def test_the_status_page_behind_a_reverse_proxy_at_a_prefix(tmp_path: Path) -> None:
    sync_api = pytest.importorskip("playwright.sync_api")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no chromium at {CHROMIUM} (deploy/browser-setup installs it)")
    if not Path(NGINX).exists():
        pytest.skip(f"no nginx at {NGINX} (deploy/browser-setup installs it)")
    bg = Background()
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.001), catalog="danfoss-fc")
    end = bg.call(sim.serve_tcp("127.0.0.1", 0))
    config = tmp_path / "pkwbus.yaml"
    config.write_text(
        "audit_db: var/audit.sqlite\nlines:\n" + line_yaml("line1", end.url, "fc", DRIVES) + "\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "PKWBUS_LISTEN"}
    run = ["run", "--config", str(config)]
    proc, port = bg.call(start_run(run, tmp_path / "run.log", env=env, cwd=tmp_path))
    expect = sync_api.expect
    try:
        with nginx(tmp_path, port) as proxy:
            base = f"http://127.0.0.1:{proxy}{PREFIX}"
            seen: list[tuple[str, int]] = []
            with sync_api.sync_playwright() as p:
                browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
                try:
                    page = browser.new_page()
                    page.route("**/*", lambda route: _only(route, proxy))
                    page.on("response", lambda r: seen.append((r.url, r.status)))
                    page.goto(base)
                    for name in ("fan1", "fan2"):  # each drive's row, then its detail
                        page.locator(f'#drives tr[data-drive="{name}"]').click(timeout=30_000)
                        detail = page.locator(f'#detail[data-drive="{name}"]')
                        ramp = detail.locator('[data-parameter="3-41"] .value')
                        expect(ramp).to_have_text(re.compile(r"^\d+(\.\d+)? s$"), timeout=30_000)
                    line = page.locator('#lines [data-line="line1"]')
                    expect(line).to_contain_text("open", timeout=30_000)
                    # Everything the page fetched went through the prefix, and was found.
                    assert seen and all(url.startswith(base) for url, _ in seen), seen
                    assert all(status < 400 for _, status in seen), seen
                    assert any("/api/v1/drives?view=overview" in url for url, _ in seen)
                    assert any("/api/v1/drives?drive=fan2" in url for url, _ in seen)
                    # Its links: the API docs (with their schema) and the metrics.
                    page.click("nav a:text('API')")
                    assert page.url == base + "docs"
                    ui = page.locator(".swagger-ui")
                    expect(ui).to_contain_text("/api/v1/drives", timeout=30_000)
                    page.goto(base)
                    page.click("nav a:text('metrics')")
                    assert page.url == base + "metrics"
                    assert "pkwbus_parameter_value" in page.content()
                    assert all(status < 400 for _, status in seen), seen
                finally:
                    browser.close()
    finally:
        proc.terminate()
        bg.call(proc.wait())
        bg.call(end.close())
        bg.close()


def _only(route: Any, proxy: int) -> None:
    """No internet, and nothing but the proxy: the page reaches pkwbus through it alone."""
    if route.request.url.startswith(f"http://127.0.0.1:{proxy}/"):
        route.continue_()
    else:
        route.abort()
