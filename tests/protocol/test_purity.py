"""The protocol layer is sans-I/O: no event loop, port, socket or clock."""

from __future__ import annotations

import ast
import pathlib

import pkwbus.protocol

FORBIDDEN = {"asyncio", "serial", "serial_asyncio", "socket", "time", "select", "selectors"}


def imported_modules(path: pathlib.Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_protocol_imports_no_io_or_clock() -> None:
    root = pathlib.Path(pkwbus.protocol.__file__).parent
    files = sorted(root.rglob("*.py"))
    assert len(files) >= 6
    for path in files:
        bad = imported_modules(path) & FORBIDDEN
        assert not bad, f"{path.name} imports {bad}"
