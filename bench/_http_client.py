"""HTTP client for the service benchmarks, run in its own process (no GIL shared with the service).

    python bench/_http_client.py put BASE_URL PATH N GAP TOKEN
    python bench/_http_client.py scrape BASE_URL N

Prints one JSON object: the latencies in seconds, the errors, and for a
scrape the size of the last answer.
"""

from __future__ import annotations

import json
import random
import sys
import time

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


def scrape(base: str, n: int) -> dict[str, object]:
    latencies: list[float] = []
    size = 0
    with httpx.Client(base_url=base, timeout=30) as client:
        for _ in range(n):
            t0 = time.perf_counter()
            r = client.get("/metrics")
            latencies.append(time.perf_counter() - t0)
            size = len(r.content)
            time.sleep(0.05)
    return {"latencies": latencies, "size": size, "errors": []}


def main() -> None:
    mode, base = sys.argv[1], sys.argv[2]
    if mode == "put":
        out = put(base, sys.argv[3], int(sys.argv[4]), float(sys.argv[5]), sys.argv[6])
    else:
        out = scrape(base, int(sys.argv[3]))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
