"""The read model has one writer: nothing in ``service/`` writes to the snapshot (each
line's snapshot writer in ``master/`` does, from the line's events), and a configured
drive (``DriveEntry``) is frozen, holding nothing a running line changes."""

from __future__ import annotations

import ast
import dataclasses
from collections.abc import Iterator
from pathlib import Path

import pytest

from pkwbus.service.runtime import DriveEntry
from tests.test_modules import PATHS

SERVICE = [p for p in PATHS if "service" in p.parts]
# What changes a dict, a list or a set in place.
MUTATORS = {"pop", "popitem", "update", "clear", "setdefault", "add", "discard", "remove",
            "append", "extend", "insert", "touch", "forget", "intersection_update"}  # fmt: skip


def _reaches_snapshot(node: ast.AST) -> bool:
    """Whether ``node`` (an assignment's target, a method's object) is the snapshot or a
    part of it: ``x.snapshot``, ``x.snapshot.readings[k]``, ``snap.drives``..."""
    while isinstance(node, ast.Attribute | ast.Subscript):
        if isinstance(node, ast.Attribute) and node.attr in {"snapshot", "_snapshot"}:
            return True
        node = node.value
    return isinstance(node, ast.Name) and node.id in {"snapshot", "snap"}


def _writes(path: Path) -> Iterator[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        targets: list[ast.AST] = []
        if isinstance(node, ast.Assign):
            targets = list(node.targets)
        elif isinstance(node, ast.AugAssign | ast.AnnAssign):
            targets = [node.target]
        elif isinstance(node, ast.Delete):
            targets = list(node.targets)
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr in MUTATORS
            and _reaches_snapshot(node.func.value)
        ):
            yield f"{path}:{node.lineno}: {ast.unparse(node)}"
        for target in targets:
            # A name bound to the model (``snap = runtime.snapshot``, ``self._snapshot =``)
            # is no write; an item or an attribute of the model set is.
            if isinstance(target, ast.Subscript | ast.Attribute) and _reaches_snapshot(
                target.value
            ):
                yield f"{path}:{node.lineno}: {ast.unparse(node)}"


def test_the_check_finds_a_write(tmp_path: Path) -> None:
    """The check itself: each kind of write it must see, seen."""
    sample = tmp_path / "sample.py"
    sample.write_text(
        "def f(runtime, snap, key, r):\n"
        "    runtime.snapshot.readings[key] = r\n"
        "    snap.lines.pop('a')\n"
        "    runtime.snapshot.drives['d'] = r\n"
        "    del runtime.snapshot.maintenance['d']\n"
        "    runtime.snapshot.changes.touch('d')\n"
        "    self.snapshot = snap\n"
        "    snap.lines = {}\n",
        encoding="utf-8",
    )
    assert len(list(_writes(sample))) == 6


def test_nothing_in_service_writes_to_the_snapshot() -> None:
    assert SERVICE, "the service's modules are found"
    found = [w for path in SERVICE for w in _writes(path)]
    assert not found, "\n".join(found)


def test_a_configured_drive_is_frozen_and_holds_nothing_mutable() -> None:
    fields = {f.name: f for f in dataclasses.fields(DriveEntry)}
    assert DriveEntry.__dataclass_params__.frozen  # type: ignore[attr-defined]
    entry = DriveEntry("d", "l", target=None)  # type: ignore[arg-type]
    with pytest.raises(dataclasses.FrozenInstanceError):
        entry.polls = ()  # type: ignore[misc]
    for name in fields:
        value = getattr(entry, name)
        assert not isinstance(value, dict | list | set), f"DriveEntry.{name} can change"
