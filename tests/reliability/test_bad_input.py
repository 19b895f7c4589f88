"""Bad input: every broken configuration makes `check-config` and `run` exit 2, naming the
place of the problem, without a traceback; the HTTP API answers bad requests with 4xx."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from pkwbus import cli
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.sim import SimTiming, Simulator
from tests.service.config.test_config import BAD, EXPECTED

from .helpers import config_text, fc_line
from .service import TOKEN

# Broken only against test_config's stand-in catalog (its 3-41 has max 100; the
# built-in one allows the override): valid with the built-in catalogs.
VALID_WITH_BUILTIN_CATALOGS = {"override_conflicts_catalog"}
CORPUS = sorted(set(EXPECTED) - VALID_WITH_BUILTIN_CATALOGS)


def place_of(name: str) -> str:
    """The place an expectation names: ``lines[0].drives[0].address`` or ``line 7, column 5``."""
    return EXPECTED[name].split(": ")[0]


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out + err


@pytest.mark.parametrize("name", CORPUS)
def test_broken_file_exits_2_naming_its_place(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = str(BAD / f"{name}.yaml")
    for argv in (["check-config", path], ["run", "--config", path, "--listen", "127.0.0.1:1"]):
        code, text = run_cli(argv, capsys)
        assert code == 2, (argv, text)
        assert place_of(name) in text, text
        assert "Traceback" not in text


def test_broken_files_through_the_real_command(tmp_path: Path) -> None:
    for name in ("address_range_fc", "yaml_syntax", "bad_duration_unit"):
        path = str(BAD / f"{name}.yaml")
        for args in (["check-config", path], ["run", "--config", path]):
            done = subprocess.run(
                [sys.executable, "-m", "pkwbus", *args], capture_output=True, text=True, timeout=60
            )
            assert done.returncode == 2, done
            assert place_of(name) in done.stderr
            assert "Traceback" not in done.stderr + done.stdout


@pytest.fixture
def unreadable(tmp_path: Path) -> Iterator[dict[str, Path]]:
    files = {"directory": tmp_path / "dir.yaml", "garbage": tmp_path / "garbage.yaml"}
    files["directory"].mkdir()
    files["garbage"].write_bytes(bytes(range(256)) * 4)
    locked = tmp_path / "locked.yaml"
    locked.write_text("lines: []\n")
    locked.chmod(0)
    files["permission"] = locked
    yield files
    locked.chmod(0o600)


def test_unreadable_files_exit_2(
    unreadable: dict[str, Path], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    if os.geteuid() == 0:  # root reads any file: make the read fail as it would for others
        locked = unreadable["permission"]
        real = Path.open

        def open_(self: Path, *args: Any, **kw: Any) -> Any:
            if self == locked:
                raise PermissionError(13, "Permission denied", str(self))
            return real(self, *args, **kw)

        monkeypatch.setattr(Path, "open", open_)
    reasons = {
        "directory": "Is a directory",
        "garbage": "not UTF-8",
        "permission": "Permission denied",
    }
    for kind, path in unreadable.items():
        for argv in (["check-config", str(path)], ["run", "--config", str(path)]):
            code, text = run_cli(argv, capsys)
            assert code == 2, (kind, text)
            assert str(path) in text and reasons[kind] in text, text
            assert "Traceback" not in text


def test_a_parameter_missing_from_the_catalog_is_not_an_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "ok.yaml"
    path.write_text(config_text([fc_line("l1", "/dev/ttyUSB0", [1], ["16-13", "16-99"])]))
    code, text = run_cli(["check-config", str(path)], capsys)
    assert code == 0, text
    assert "NOTE" in text and "16-99 is not in catalog danfoss-fc" in text


# ------------------------------------------------------------------- API


@pytest.fixture
async def api() -> AsyncIterator[httpx.AsyncClient]:
    """The app behind a real uvicorn server (chunked bodies need a real HTTP parser)."""
    import uvicorn

    from pkwbus.service.assembly.serve import bind
    from pkwbus.service.http.api import create_app

    sim = Simulator("fc", [1], timing=SimTiming(0.001), seed=1, catalog="danfoss-fc")
    end = await sim.serve_tcp("127.0.0.1", 0)
    text = config_text([fc_line("l1", end.url, [1], ["16-13"], every="1s")])
    runtime = await build_runtime(parse_config(text, environ={}))
    await runtime.start()
    while any(
        d.pending for d in runtime.snapshot.decoding.values()
    ):  # writes wait for descriptions
        await asyncio.sleep(0.01)
    sock = bind("127.0.0.1", 0)
    port = sock.getsockname()[1]
    app = create_app(runtime, write_token=TOKEN)
    server = uvicorn.Server(uvicorn.Config(app, log_config=None, lifespan="off"))
    task = asyncio.create_task(server.serve(sockets=[sock]))
    while not server.started:
        await asyncio.sleep(0.01)
    try:
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
            yield client
    finally:
        server.should_exit = True
        await task
        sock.close()
        await runtime.stop()
        await end.close()


WRITE = "/api/v1/drives/l1_d1/parameters/3-41"
AUTH = {"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"}


async def test_api_bad_requests_are_4xx(api: httpx.AsyncClient) -> None:
    bodies: list[bytes] = [
        b"{",
        b"not json",
        b"\xff\xfe\x00",
        b"[]",
        b"null",
        b'{"value": "ten"}',
        b'{"value": [1]}',
        b'{"value": {"a": 1}}',
        b'{"value": 1, "index": -1}',
        b'{"value": 1, "index": "x"}',
        b'{"value": 1, "store": "flash"}',
        b'{"value": 1, "extra": true}',
        b'{"value": 1e400}',
        b'{"value": NaN}',
        b'{"value": 123456789012345678901234567890}',
        b"{}",
    ]
    for body in bodies:
        response = await api.put(WRITE, content=body, headers=AUTH)
        assert 400 <= response.status_code < 500, (body, response.status_code, response.text)
    for url in (
        "/api/v1/drives/l1_d1/parameters/3-41?index=x",
        "/api/v1/drives/l1_d1/parameters/3-41?index=99999",
        "/api/v1/drives/l1_d1/parameters/99999999",
        "/api/v1/drives/l1_d1/parameters/%00",
        "/api/v1/drives/nobody/parameters/3-41",
        "/api/v1/audit?limit=-1",
        "/api/v1/audit?limit=abc",
    ):
        response = await api.get(url)
        assert 400 <= response.status_code < 500, (url, response.status_code, response.text)


async def test_api_huge_bodies_are_refused(api: httpx.AsyncClient) -> None:
    big = b'{"value": 1, "pad": "' + b"x" * (4 * 2**20) + b'"}'
    response = await api.put(WRITE, content=big, headers=AUTH)
    assert response.status_code == 413, response.text

    async def chunks() -> AsyncIterator[bytes]:
        yield b'{"value": 1, "pad": "'
        for _ in range(64):
            yield b"x" * 2**16
        yield b'"}'

    response = await api.put(WRITE, content=chunks(), headers=AUTH)
    assert response.status_code == 413, response.text  # refused while it streams in
    # A Content-Length far beyond what is sent: refused from the header alone.
    url = httpx.URL(str(api.base_url))
    reader, writer = await asyncio.open_connection(url.host, url.port)
    writer.write(
        f"PUT {WRITE} HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\n"
        f"Content-Type: application/json\r\nContent-Length: {10**12}\r\n\r\n".encode()
        + b'{"value": 1'
    )
    await writer.drain()
    status = await asyncio.wait_for(reader.readline(), 10)
    writer.close()
    assert status.split()[1].startswith(b"4"), status
