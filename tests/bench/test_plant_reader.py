"""bench.plant_scale's reader (what its GET /metrics and GET /api/v1/drives figures time):
every byte of an answer, over a kept-alive connection and again after the server closed it."""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import ClassVar

import pytest

from bench.plant_scale import _Reader


class _Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"  # kept alive unless the server says otherwise
    bodies: ClassVar[list[bytes]] = []

    def do_GET(self) -> None:
        body = self.bodies.pop(0)
        self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        if self.path == "/close":
            self.send_header("Connection", "close")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture
def server() -> Iterator[str]:
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}"
    finally:
        httpd.shutdown()
        httpd.server_close()


def test_the_reader_gets_each_answer_whole_and_comes_back_after_a_close(server: str) -> None:
    bodies = [os.urandom(3_000_017), os.urandom(11), os.urandom(200_003)]
    _Handler.bodies = list(bodies)
    reader = _Reader(server)
    reader.buffer = bytearray(1_000_000)  # smaller than the first answer: it grows
    try:
        status, body, elapsed = reader.get("/metrics")
        assert (status, bytes(body)) == (200, bodies[0])
        assert elapsed > 0
        status, body, _ = reader.get("/close")  # the server closes after this answer
        assert (status, bytes(body)) == (200, bodies[1])
        status, body, _ = reader.get("/metrics")
        assert (status, bytes(body)) == (200, bodies[2])
        assert reader.reconnects == 1
    finally:
        reader.close()
