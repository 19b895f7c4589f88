"""Requests without a valid token cost no disk: `pkwbus run` counts them in memory and
writes one row per address and minute once the minute has ended, or at shutdown.

10,000 hostile requests over loopback, from three source addresses, grow the audit
files (database, write-ahead log and its index) by less than 100 KB, and the rows
written add up to what each address sent, one per address and minute. The sizes
are printed (``pytest -s``) so they can be quoted.
"""

from __future__ import annotations

import asyncio
import re
import signal
import sqlite3
import time
from collections import Counter, defaultdict
from pathlib import Path

from pkwbus.sim import SimTiming, Simulator

from .service import Service

WRITE = "/api/v1/drives/l1_d1/parameters/3-41"
BODY = b'{"value": 38}'
GROWTH = 100_000  # bytes the audit files may grow by for the whole flood
BATCH = 50  # requests written on a connection before their answers are read
# source address -> (kind of refusal, requests): 10,000 in all
FLOOD = {
    "127.0.0.2": {"unauthenticated": 3000, "forbidden": 1000},
    "127.0.0.3": {"unauthenticated": 3500},
    "127.0.0.4": {"forbidden": 2500},
}


def request(kind: str, path: str = WRITE) -> bytes:
    """One PUT without a valid token: no Authorization (unauthenticated) or a wrong one."""
    auth = b"" if kind == "unauthenticated" else b"Authorization: Bearer guess-4711\r\n"
    return (
        f"PUT {path} HTTP/1.1\r\nHost: pkwbus\r\nContent-Type: application/json\r\n".encode()
        + auth
        + f"Content-Length: {len(BODY)}\r\n\r\n".encode()
        + BODY
    )


async def answer(reader: asyncio.StreamReader) -> int:
    """The status of the next answer on the connection, its body read past."""
    head = (await reader.readuntil(b"\r\n\r\n")).decode("latin-1")
    length = re.search(r"(?im)^content-length:\s*(\d+)", head)
    assert length is not None, head
    await reader.readexactly(int(length.group(1)))
    return int(head.split(" ", 2)[1])


async def send(port: int, source: str, kinds: dict[str, int]) -> Counter[int]:
    """Send ``kinds`` of refused requests from ``source`` on one kept-alive connection."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0))
    plan = [kind for kind, n in kinds.items() for _ in range(n)]
    statuses: Counter[int] = Counter()
    try:
        for start in range(0, len(plan), BATCH):
            batch = plan[start : start + BATCH]
            writer.write(b"".join(request(kind) for kind in batch))
            await writer.drain()
            for _ in batch:
                statuses[await answer(reader)] += 1
    finally:
        writer.close()
    return statuses


def audit_bytes(db: Path) -> int:
    """The audit files' size on disk: the database, its write-ahead log and its index."""
    files = [db, db.with_name(db.name + "-wal"), db.with_name(db.name + "-shm")]
    return sum(f.stat().st_size for f in files if f.exists())


def refusal_rows(db: Path) -> list[tuple[str, float, int, str]]:
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as look:
        return look.execute(
            "SELECT client, time, count, detail FROM writes WHERE outcome = 'refused'"
        ).fetchall()


def kinds_of(detail: str) -> Counter[str]:
    """``refused without a valid token: forbidden 3, unauthenticated 5`` as a Counter."""
    return Counter({k: int(n) for k, n in re.findall(r"(\w+) (\d+)", detail.split(":", 1)[1])})


async def test_ten_thousand_refusals_grow_the_audit_files_by_less_than_100_kb(
    tmp_path: Path,
) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(0.002), seed=1, catalog="danfoss-fc")
    end = await sim.serve_tcp("127.0.0.1", 0)
    service = Service(tmp_path, end.url)
    try:
        await service.start()
        before = audit_bytes(service.audit_db)
        first_minute = int(time.time() // 60)
        sent = await asyncio.wait_for(
            asyncio.gather(*(send(service.port, src, kinds) for src, kinds in FLOOD.items())),
            timeout=600,
        )
        last_minute = int(time.time() // 60)
        running = audit_bytes(service.audit_db)
        service.signal(signal.SIGTERM)
        assert await service.wait(30.0) == 0
    finally:
        await service.stop()
        await end.close()
    stopped = audit_bytes(service.audit_db)
    total = sum(n for kinds in FLOOD.values() for n in kinds.values())
    print(
        f"\naudit files (database + WAL + SHM) before {before} B; after {total} refused"
        f" requests {running} B running (+{running - before} B), {stopped} B stopped"
    )
    for (src, kinds), statuses in zip(FLOOD.items(), sent, strict=True):
        expected = {401: kinds.get("unauthenticated", 0), 403: kinds.get("forbidden", 0)}
        assert statuses == Counter(expected), src
    assert running - before < GROWTH
    assert stopped - before < GROWTH

    rows = refusal_rows(service.audit_db)
    by_client: defaultdict[str, list[tuple[float, int, str]]] = defaultdict(list)
    for client, at, count, detail in rows:
        by_client[client].append((at, count, detail))
    assert set(by_client) == set(FLOOD), rows
    for src, kinds in FLOOD.items():
        mine = by_client[src]
        minutes = [int(at // 60) for at, _, _ in mine]
        assert len(set(minutes)) == len(minutes), f"{src}: two rows in one minute: {mine}"
        assert all(first_minute <= m <= last_minute for m in minutes), (mine, first_minute)
        assert sum(count for _, count, _ in mine) == sum(kinds.values())
        counted = sum((kinds_of(detail) for _, _, detail in mine), Counter())
        assert counted == Counter(kinds)
        assert all(sum(kinds_of(d).values()) == count for _, count, d in mine)
    assert "Traceback" not in service.log.read_text()


async def test_counts_not_yet_written_are_written_at_shutdown(tmp_path: Path) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(0.002), seed=1, catalog="danfoss-fc")
    end = await sim.serve_tcp("127.0.0.1", 0)
    service = Service(tmp_path, end.url)
    source, in_one_minute = "", False
    try:
        await service.start()
        # A count is written once its minute has ended: three refusals, and a look at the
        # database within the same minute finds nothing. At a minute's turn, again from
        # another address.
        for source in ("127.0.0.5", "127.0.0.6", "127.0.0.7"):
            minute = int(time.time() // 60)
            statuses = await send(service.port, source, {"unauthenticated": 2, "forbidden": 1})
            assert statuses == Counter({401: 2, 403: 1})
            written = [row for row in refusal_rows(service.audit_db) if row[0] == source]
            in_one_minute = int(time.time() // 60) == minute
            if in_one_minute:
                break
        assert in_one_minute, "three minutes turned during three refusals each"
        assert written == [], "the count was written before its minute ended"
        service.signal(signal.SIGTERM)
        assert await service.wait(30.0) == 0
    finally:
        await service.stop()
        await end.close()
    assert "Traceback" not in service.log.read_text()
    ((_, _, count, detail),) = [row for row in refusal_rows(service.audit_db) if row[0] == source]
    assert count == 3
    assert kinds_of(detail) == Counter({"unauthenticated": 2, "forbidden": 1})
