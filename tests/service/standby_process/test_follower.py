"""The follower's log is what the process tests judge by: it must attribute each connection
to the process that opened it and find two connections that transmitted at the same time."""

from __future__ import annotations

import asyncio
import os

from pkwbus.protocol.serial.telegram import fc_adr, frame

from .follower import UNKNOWN, Connection, Follower, Request, overlaps


def conns(*owners: str) -> list[Connection]:
    return [Connection(i, o, ("127.0.0.1", 0), 0.0) for i, o in enumerate(owners, start=1)]


def test_interleaved_requests_of_two_connections_overlap_and_successive_ones_do_not() -> None:
    two = conns("a", "b")
    after = [Request(1, "a", 1.0), Request(1, "a", 2.0), Request(2, "b", 2.5), Request(2, "b", 4)]
    assert overlaps(after, two) == []
    inside = [*after, Request(1, "a", 3.0)]  # a sent once more while b was transmitting
    (found,) = overlaps(inside, two)
    assert (found.first.owner, found.second.owner) == ("a", "b")
    assert found.first_span == (1.0, 3.0) and found.second_span == (2.5, 4)
    assert "connection 1 (a)" in str(found)


def test_a_master_that_reopened_its_port_has_two_connections_one_after_the_other() -> None:
    three = conns("a", "a", "b")
    log = [Request(1, "a", 1.0), Request(2, "a", 2.0), Request(3, "b", 3.0)]
    assert overlaps(log, three) == []
    assert len(overlaps([*log, Request(2, "a", 3.5)], three)) == 1


async def test_each_connection_is_named_by_the_process_that_holds_it() -> None:
    line = Follower()
    line.owners[os.getpid()] = "me"
    await line.start()
    try:
        request = frame(fc_adr(1), bytes(12))  # a PKW request with nothing asked, drive 1
        reader, writer = await asyncio.open_connection("127.0.0.1", line.port)
        writer.write(request)
        answer = await asyncio.wait_for(reader.read(64), 10)
        assert answer[2] == fc_adr(1)
        del line.owners[os.getpid()]
        other_reader, other = await asyncio.open_connection("127.0.0.1", line.port)
        other.write(request)
        await asyncio.wait_for(other_reader.read(64), 10)
        assert [(r.conn, r.owner) for r in line.requests] == [(1, "me"), (2, UNKNOWN)]
        assert len(line.open_connections()) == 2
        writer.close()
        other.close()
        await asyncio.sleep(0)
    finally:
        await line.close()
    assert line.open_connections() == []
