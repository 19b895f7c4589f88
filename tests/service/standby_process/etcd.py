"""A real etcd of one or three members on loopback, each in its own temp folder, for the hot
standby's process tests and its benchmark: members are killed (SIGKILL) and started again on
the same ports and data (or, wiped, as a new empty store on the same ports), the leader is
found from the members' own status, and the gRPC requests served are counted from each
member's ``/metrics``.

Debian's ``etcd-server`` provides ``etcd``; :func:`etcd_binary` is None where it is missing.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import os
import re
import shutil
import signal
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import httpx


def etcd_binary() -> str | None:
    return shutil.which("etcd") or (
        "/usr/bin/etcd" if os.access("/usr/bin/etcd", os.X_OK) else None
    )


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class EtcdError(Exception):
    """An etcd member did not come up or did not answer."""


@dataclass
class Member:
    name: str
    client_port: int
    peer_port: int
    data: Path
    proc: subprocess.Popen[bytes] | None = None
    log: IO[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.client_port}"

    @property
    def peer_url(self) -> str:
        return f"http://127.0.0.1:{self.peer_port}"

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None


@dataclass
class Etcd:
    """``size`` members named m0.. in ``root``; :meth:`start` runs them all."""

    root: Path
    size: int = 1
    members: list[Member] = field(default_factory=list)

    def __post_init__(self) -> None:
        binary = etcd_binary()
        if binary is None:
            raise EtcdError("etcd is not installed (Debian package etcd-server)")
        self.binary = binary
        for i in range(self.size):
            data = self.root / f"m{i}"
            self.members.append(Member(f"m{i}", free_port(), free_port(), data))
        self.cluster = ",".join(f"{m.name}={m.peer_url}" for m in self.members)

    @property
    def endpoints(self) -> list[str]:
        return [m.url for m in self.members]

    def launch(self, member: Member) -> None:
        """Start one member (again: on its ports and data as before)."""
        assert not member.running, f"{member.name} runs already"
        member.data.mkdir(parents=True, exist_ok=True)
        state = "existing" if (member.data / "member").exists() else "new"
        member.log = (self.root / f"{member.name}.log").open("ab")
        member.proc = subprocess.Popen(
            [
                self.binary,
                "--name", member.name,
                "--data-dir", str(member.data / ""),
                "--listen-client-urls", member.url,
                "--advertise-client-urls", member.url,
                "--listen-peer-urls", member.peer_url,
                "--initial-advertise-peer-urls", member.peer_url,
                "--initial-cluster", self.cluster,
                "--initial-cluster-state", state,
                "--initial-cluster-token", f"pkwbus-test-{os.getpid()}",
                "--logger", "zap",
                "--log-level", "warn",
            ],
            stdout=member.log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )  # fmt: skip

    async def start(self, timeout: float = 30.0) -> None:
        for member in self.members:
            self.launch(member)
        await self.wait_healthy(self.members, timeout)

    async def wait_healthy(self, members: list[Member], timeout: float = 30.0) -> None:
        """Until each of ``members`` answers /health true (the cluster has a leader)."""
        end = time.monotonic() + timeout
        async with httpx.AsyncClient(timeout=2) as client:
            for member in members:
                while True:
                    with contextlib.suppress(httpx.HTTPError, ValueError):
                        r = await client.get(f"{member.url}/health")
                        if r.json().get("health") == "true":
                            break
                    if member.proc is not None and member.proc.poll() is not None:
                        raise EtcdError(f"etcd {member.name} exited:\n{self.log_of(member)}")
                    if time.monotonic() > end:
                        raise EtcdError(f"etcd {member.name} not healthy:\n{self.log_of(member)}")
                    await asyncio.sleep(0.1)

    def kill(self, member: Member) -> None:
        """SIGKILL: no goodbye to the peers or the clients."""
        if member.proc is not None and member.proc.poll() is None:
            member.proc.send_signal(signal.SIGKILL)
            member.proc.wait()
        if member.log is not None:
            member.log.close()
            member.log = None

    def wipe(self, member: Member) -> None:
        """SIGKILL, and its data deleted: launched again, it is a new, empty store on the same
        ports, its revisions started anew (one member only: a wiped member of three would
        not join its peers again)."""
        assert self.size == 1, "only the member of a one-member etcd can be wiped"
        self.kill(member)
        shutil.rmtree(member.data, ignore_errors=True)

    def stop(self) -> None:
        for member in self.members:
            self.kill(member)

    def log_of(self, member: Member) -> str:
        path = self.root / f"{member.name}.log"
        return path.read_text(errors="replace")[-3000:] if path.exists() else ""

    async def leader(self) -> Member:
        """The member the running members name as their leader."""
        async with httpx.AsyncClient(timeout=2) as client:
            for member in self.members:
                if not member.running:
                    continue
                with contextlib.suppress(httpx.HTTPError, ValueError, KeyError):
                    r = await client.post(f"{member.url}/v3/maintenance/status", json={})
                    status = r.json()
                    if str(status["leader"]) == str(status["header"]["member_id"]):
                        return member
        raise EtcdError("no member says it is the leader")

    async def keys(self, prefix: str) -> dict[str, bytes]:
        """The keys under ``prefix`` and their values, from any running member."""
        return {key: value for key, (value, _) in (await self.entries(prefix)).items()}

    async def entries(self, prefix: str) -> dict[str, tuple[bytes, int]]:
        """The keys under ``prefix``: their values and the revisions that created them."""
        start = prefix.encode()
        end = start[:-1] + bytes([start[-1] + 1])
        body = {"key": _b64(start), "range_end": _b64(end)}
        async with httpx.AsyncClient(timeout=2) as client:
            for member in self.members:
                if not member.running:
                    continue
                with contextlib.suppress(httpx.HTTPError, ValueError):
                    r = await client.post(f"{member.url}/v3/kv/range", json=body)
                    kvs = r.json().get("kvs", [])
                    return {
                        base64.b64decode(kv["key"]).decode(): (
                            base64.b64decode(kv.get("value", "")),
                            int(kv["create_revision"]),
                        )
                        for kv in kvs
                    }
        raise EtcdError("no member answered")

    async def put(self, key: str, value: bytes) -> int:
        """``key`` set to ``value`` on any running member: the store's revision after it."""
        body = {"key": _b64(key.encode()), "value": _b64(value)}
        async with httpx.AsyncClient(timeout=2) as client:
            for member in self.members:
                if not member.running:
                    continue
                with contextlib.suppress(httpx.HTTPError, ValueError, KeyError):
                    r = await client.post(f"{member.url}/v3/kv/put", json=body)
                    return int(r.json()["header"]["revision"])
        raise EtcdError("no member answered")

    async def served(self) -> dict[str, float]:
        """Requests served so far, summed over the running members' /metrics: finished gRPC
        calls (``grpc_server_handled_total``) and gRPC messages received
        (``grpc_server_msg_received_total``: each lease keep-alive on a stream is one)."""
        totals = {"grpc_server_handled_total": 0.0, "grpc_server_msg_received_total": 0.0}
        async with httpx.AsyncClient(timeout=5) as client:
            for member in self.members:
                if member.running:
                    text = (await client.get(f"{member.url}/metrics")).text
                    for name in totals:
                        totals[name] += sum_metric(text, name)
        return totals


METRIC_LINE = re.compile(r"^(\w+)(?:\{[^}]*\})?\s+(\S+)$", re.M)


def sum_metric(text: str, name: str) -> float:
    """The sum of every series of ``name`` in a Prometheus text exposition."""
    return sum(float(m.group(2)) for m in METRIC_LINE.finditer(text) if m.group(1) == name)


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode()
