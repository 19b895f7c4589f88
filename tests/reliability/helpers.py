"""What the reliability tests share: simulators on TCP, a service configuration, recorders."""

from __future__ import annotations

import asyncio
import contextlib
import errno
import os
import shutil
import subprocess
import textwrap
from collections import Counter, defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.buses import decode_adr
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.protocol.serial.telegram import Telegram, split_block
from pkwbus.sim import Simulator
from pkwbus.sim.drives.faults import Answer

WRITE_COMMANDS = frozenset(c for c in Command if c.name.startswith("WRITE"))


@dataclass
class WireLog:
    """What one simulator put on the wire in valid telegrams, and what it was asked.

    ``values[(address, pnu, subindex)]`` holds every value response that left
    the simulator inside a telegram with a good checksum (after its fault was
    applied: a dropped or corrupted answer is not there; a garbage prefix is
    skipped, a stale one is there again). ``writes[address]`` counts the write
    requests that reached each drive.
    """

    values: defaultdict[tuple[int, int, int], set[pkw.ValueResponse]] = field(
        default_factory=lambda: defaultdict(set)
    )
    writes: Counter[int] = field(default_factory=Counter)
    requests: Counter[int] = field(default_factory=Counter)


def record_wire(sim: Simulator) -> WireLog:
    """Wrap ``sim.answer`` so that every request and every answer sent is logged."""
    log = WireLog()
    answer = sim.answer

    def logged(telegram: Telegram, now: float | None = None) -> Answer | None:
        _log_request(sim, log, telegram)
        out = answer(telegram, now)
        if out is not None:
            for event in sim.deframer().feed(out.data):
                if isinstance(event, Telegram):
                    _log_answer(sim, log, event)
        return out

    sim.answer = logged  # type: ignore[method-assign]
    return log


def _log_request(sim: Simulator, log: WireLog, telegram: Telegram) -> None:
    address = decode_adr(sim.protocol, telegram.adr).address
    log.requests[address] += 1
    try:
        block = split_block(telegram.data, sim.shape)
        if len(block.pkw) < 4:
            return
        req = pkw.decode_request(block.pkw, sim.dialect, sim.layout)
    except RemoteProtocolError:
        return
    if req.command in WRITE_COMMANDS:
        log.writes[address] += 1


def _log_answer(sim: Simulator, log: WireLog, telegram: Telegram) -> None:
    address = decode_adr(sim.protocol, telegram.adr).address
    try:
        block = split_block(telegram.data, sim.shape)
        if len(block.pkw) < 4:
            return
        resp = pkw.decode_response(block.pkw, sim.dialect, sim.layout)
    except RemoteProtocolError:
        return
    if isinstance(resp, pkw.ValueResponse):
        log.values[address, resp.pnu, resp.subindex].add(resp)


def config_text(lines: list[dict[str, Any]], *, audit_db: str = ":memory:", **top: Any) -> str:
    """A service configuration in YAML from plain dictionaries (JSON is YAML)."""
    import json

    body = {"audit_db": audit_db, **top, "lines": lines}
    return json.dumps(body, indent=1)


def fc_line(
    name: str, url: str, addresses: list[int], polls: list[str], **extra: Any
) -> dict[str, Any]:
    every = extra.pop("every", "50ms")
    return {
        "name": name,
        "port": url,
        "protocol": "fc",
        "baudrate": 115200,
        "timeout": extra.pop("timeout", "250ms"),
        "retries": extra.pop("retries", 2),
        **extra,
        "drives": [
            {
                "name": f"{name}_d{a}",
                "address": a,
                "catalog": "danfoss-fc",
                "poll": [{"parameter": p, "every": every} for p in polls],
                "writable": ["3-41", "3-42"],
            }
            for a in addresses
        ],
    }


def uss_line(
    name: str, url: str, addresses: list[int], polls: list[str], **extra: Any
) -> dict[str, Any]:
    line = fc_line(name, url, addresses, polls, **extra)
    line["protocol"] = "uss"
    for drive in line["drives"]:
        drive["catalog"] = "siemens-g120"
        drive["writable"] = ["p1120", "p1121"]
    return line


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


async def wait_for(check: Callable[[], bool], timeout: float, step: float = 0.02) -> float:
    """Seconds until ``check()`` holds; TimeoutError after ``timeout``."""
    loop = asyncio.get_running_loop()
    start = loop.time()
    while not check():
        if loop.time() - start > timeout:
            raise TimeoutError(f"not within {timeout} s")
        await asyncio.sleep(step)
    return loop.time() - start


def dedent(text: str) -> str:
    return textwrap.dedent(text).lstrip()


@contextlib.contextmanager
def tmpfs(where: Path, size: str, *, readonly: bool = False) -> Iterator[Path]:
    """A small file system of its own at ``where``, for as long as the block runs;
    the test is skipped where it cannot be mounted (not root, a container without
    CAP_SYS_ADMIN)."""
    where.mkdir(parents=True, exist_ok=True)
    options = f"size={size},mode=0755" + (",ro" if readonly else "")
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a small file system needs root")
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def fill(folder: Path) -> Path:
    """A file that takes every free byte of ``folder``'s file system."""
    filler = folder / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        for size in (2**16, 2**12, 2**9, 1):
            while True:
                try:
                    os.write(fd, b"\0" * size)
                except OSError as exc:
                    if exc.errno != errno.ENOSPC:
                        raise
                    break
    finally:
        os.close(fd)
    return filler
