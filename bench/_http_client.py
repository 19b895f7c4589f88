"""HTTP client for the service benchmarks, run in its own process (no GIL shared with the service).

    python -m bench._http_client put BASE_URL PATH N GAP TOKEN
    python -m bench._http_client scrape BASE_URL N [GAP]

Prints one JSON object: the latencies in seconds, the errors, and for a
scrape the size of the last answer.
"""

from __future__ import annotations

import json
import random
import socket
import sys
import time
from urllib.parse import urlsplit

import httpx


def put(base: str, path: str, n: int, gap: float, token: str) -> dict[str, object]:
    rng = random.Random(1)
    headers = {"Authorization": f"Bearer {token}"}
    latencies: list[float] = []
    errors: list[str] = []
    with httpx.Client(base_url=base, timeout=10) as client:
        for i in range(n):
            time.sleep(gap * (0.5 + rng.random()))
            t0 = time.perf_counter()
            r = client.put(path, json={"value": 1.0 + (i % 50) / 10}, headers=headers)
            elapsed = time.perf_counter() - t0
            if r.status_code == 200:
                latencies.append(elapsed)
            else:
                errors.append(f"{r.status_code} {r.text[:200]}")
    return {"latencies": latencies, "errors": errors}


def scrape(base: str, n: int, gap: float = 0.05) -> dict[str, object]:
    """``n`` GET /metrics on one kept-alive connection, ``gap`` seconds apart.

    A plain socket that reads the body into one buffer, as Prometheus's Go client
    does: an HTTP library in Python would add its own parsing of the 10 MB body to
    every figure.
    """
    url = urlsplit(base)
    request = f"GET /metrics HTTP/1.1\r\nHost: {url.netloc}\r\n\r\n".encode()
    latencies: list[float] = []
    size = 0
    with socket.create_connection((url.hostname, url.port), timeout=30) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for _ in range(n):
            t0 = time.perf_counter()
            sock.sendall(request)
            size = _read_response(sock)
            latencies.append(time.perf_counter() - t0)
            time.sleep(gap)
    return {"latencies": latencies, "size": size, "errors": []}


def _read_response(sock: socket.socket) -> int:
    """Read one response with a Content-Length; the body's size."""
    head = b""
    while b"\r\n\r\n" not in head:
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("the service closed the connection")
        head += chunk
    head, _, body_start = head.partition(b"\r\n\r\n")
    length = next(
        int(line.split(b":", 1)[1])
        for line in head.split(b"\r\n")
        if line.lower().startswith(b"content-length:")
    )
    body = bytearray(length)
    view = memoryview(body)
    got = len(body_start)
    view[:got] = body_start
    while got < length:
        read = sock.recv_into(view[got:])
        if not read:
            raise ConnectionError("the service closed the connection")
        got += read
    return length


def main() -> None:
    mode, base = sys.argv[1], sys.argv[2]
    if mode == "put":
        out = put(base, sys.argv[3], int(sys.argv[4]), float(sys.argv[5]), sys.argv[6])
    else:
        out = scrape(base, int(sys.argv[3]), float(sys.argv[4]) if len(sys.argv) > 4 else 0.05)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
