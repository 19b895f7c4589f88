"""The read model has one writer: nothing in ``service/`` writes to the snapshot (each
line's snapshot writer in ``master/`` does, from the line's events), and a configured
drive (``DriveEntry``) is frozen, holding nothing a running line changes. A load of the
configuration (``Load``) is frozen too: nothing writes to a runtime's or a load's parts but
the runtime itself and the assembly's builder (a reload swaps a new load in whole)."""

from __future__ import annotations

import ast
import asyncio
import dataclasses
from collections.abc import Iterator
from pathlib import Path

import pytest

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.planning.jobs import Cancelled, JobKind
from pkwbus.master.snapshot import Snapshot
from pkwbus.service.assembly.loading import LoadBuilder
from pkwbus.service.runtime import DriveEntry, Load, Runtime
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


def _targets(node: ast.AST) -> list[ast.AST]:
    """What ``node`` assigns to or deletes (none: it is no assignment)."""
    if isinstance(node, ast.Assign | ast.Delete):
        return list(node.targets)
    if isinstance(node, ast.AugAssign | ast.AnnAssign):
        return [node.target]
    return []


def _writes(path: Path) -> Iterator[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        targets = _targets(node)
        if (
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


# What may write to a runtime or a load: the runtime itself, and the assembly's builder.
RUNTIME_WRITERS = {("service", "runtime.py"), ("assembly", "loading.py")}
# A runtime or a load, by the names it goes by (the builder's are others: ``next_load``);
# a bare ``load`` is one only where the module knows ``Load`` (elsewhere: a bus's load).
RUNTIME_NAMES = {"runtime", "_runtime", "load", "_load"}
LOAD_NAMES = {"load", "_load"}


def _reaches_runtime(node: ast.AST, names: set[str]) -> bool:
    """Whether ``node`` is a runtime or a load or a part of one: ``runtime.closers``,
    ``self.runtime.starters``, ``runtime.load.base``, ``load.runners[k]``..."""
    while isinstance(node, ast.Attribute | ast.Subscript):
        if isinstance(node, ast.Attribute) and node.attr in RUNTIME_NAMES:
            return True
        node = node.value
    return isinstance(node, ast.Name) and node.id in names


def _knows_load(tree: ast.Module) -> bool:
    return any(
        isinstance(n, ast.ImportFrom) and any(a.name == "Load" for a in n.names)
        for n in ast.walk(tree)
    )


def _runtime_writes(path: Path) -> Iterator[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = RUNTIME_NAMES if _knows_load(tree) else RUNTIME_NAMES - LOAD_NAMES

    def _reaches(node: ast.AST) -> bool:
        return _reaches_runtime(node, names)

    for node in ast.walk(tree):
        targets = _targets(node)
        if isinstance(node, ast.Call):
            func = node.func
            changes = isinstance(func, ast.Attribute) and (
                func.attr in MUTATORS | {"insert"} and _reaches(func.value)
            )
            sets = (
                isinstance(func, ast.Name | ast.Attribute)
                and ast.unparse(func).rpartition(".")[2] in {"setattr", "__setattr__"}
                and bool(node.args)
                and _reaches(node.args[0])
            )
            if changes or sets:
                yield f"{path}:{node.lineno}: {ast.unparse(node)}"
        for target in targets:
            # A name bound to a runtime (``self.runtime = runtime``) is no write; an
            # attribute or an item of one set is.
            if isinstance(target, ast.Subscript | ast.Attribute) and _reaches(target.value):
                yield f"{path}:{node.lineno}: {ast.unparse(node)}"


def test_the_runtime_check_finds_a_write(tmp_path: Path) -> None:
    """The check itself: each kind of write to a runtime or a load seen, and what is none
    (a name bound, the builder, a read, a method of a part the process keeps) left."""
    sample = tmp_path / "sample.py"
    sample.write_text(
        "from pkwbus.service.runtime import Load\n"
        "def f(self, runtime, load, next_load, parts, x):\n"
        "    runtime.drives = {}\n"
        "    runtime.closers['a'] = x\n"
        "    self.runtime.starters.append(x)\n"
        "    runtime.load.base += (x,)\n"
        "    del load.runners['a']\n"
        "    setattr(runtime, 'masters', x)\n"
        "    object.__setattr__(self._load, 'history', x)\n"
        "    load.cleanups.insert(0, x)\n"
        "    self.runtime = runtime\n"
        "    next_load.runners['a'] = x\n"
        "    next_load.starters.append(x)\n"
        "    parts.entries['a'] = x\n"
        "    x = runtime.drives['a']\n"
        "    runtime.outputs.swap([x])\n",
        encoding="utf-8",
    )
    found = list(_runtime_writes(sample))
    assert len(found) == 8, found
    bus = tmp_path / "bus.py"  # a bus's load where no Load is known: none of the runtime's
    bus.write_text("def f(load, x):\n    load.warnings.append(x)\n", encoding="utf-8")
    assert not list(_runtime_writes(bus))
    bus.write_text("def f(runtime, x):\n    runtime.load.warnings.append(x)\n", encoding="utf-8")
    assert len(list(_runtime_writes(bus))) == 1


def test_nothing_but_the_runtime_and_the_builder_writes_to_a_load() -> None:
    checked = [p for p in PATHS if (p.parent.name, p.name) not in RUNTIME_WRITERS]
    assert len(checked) == len(PATHS) - len(RUNTIME_WRITERS), "the writers are found"
    found = [w for path in checked for w in _runtime_writes(path)]
    assert not found, "\n".join(found)


def test_a_load_is_frozen_and_holds_nothing_mutable() -> None:
    entry = DriveEntry("d", "l", target=None)  # type: ignore[arg-type]
    load = Load(drives={"d": entry}, starters=[], closers={"l": print})
    with pytest.raises(dataclasses.FrozenInstanceError):
        load.drives = {}  # type: ignore[misc]
    with pytest.raises(TypeError):
        load.drives["e"] = entry  # type: ignore[index]
    for field in dataclasses.fields(Load):
        value = getattr(load, field.name)
        assert not isinstance(value, dict | list | set), f"Load.{field.name} can change"
    # The builder's changes reach the next load, never the one it was made from.
    building = LoadBuilder(load)
    building.starters.append(print)  # type: ignore[arg-type]
    building.closers.pop("l")
    frozen = building.freeze()
    assert (load.starters, dict(load.closers)) == ((), {"l": print})
    assert (frozen.starters, dict(frozen.closers)) == ((print,), {})
    # The runtime's view of its load: read, never set.
    runtime = Runtime(Snapshot(), None, load)  # type: ignore[arg-type]
    with pytest.raises(AttributeError):
        runtime.drives = {}  # type: ignore[misc]
    runtime.swap(frozen)
    assert runtime.load is frozen and runtime.drives == {"d": entry}


class _Line:
    """A line's runner that takes jobs until it is stopped."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.jobs: list[object] = []
        self.stopped = asyncio.Event()

    def submit(self, job: object) -> None:
        self.jobs.append(job)

    def stop(self) -> None:
        self.stopped.set()

    def forget(self) -> None:
        pass

    async def run(self) -> None:
        await self.stopped.wait()


async def test_a_line_stopped_takes_no_job_and_each_closer_runs_once() -> None:
    """The runtime's own part of a change: a line stopped before the next load is swapped
    in takes no job from then on; a line's closer and a cleanup run once, whoever calls."""
    entry = DriveEntry("d", "l", target=None)  # type: ignore[arg-type]
    line, closed, cleaned = _Line("l"), [], []
    close = lambda: closed.append(1)  # noqa: E731
    load = Load(runners={"l": line}, drives={"d": entry}, closers={"l": close},
                cleanups=[lambda: cleaned.append(1)])  # fmt: skip
    runtime = Runtime(Snapshot(), None, load)  # type: ignore[arg-type]
    await runtime.start()
    job = runtime.submit("d", None, JobKind.READ, ParameterDescription())  # type: ignore[arg-type]
    assert len(line.jobs) == 1 and not job.done()
    await runtime.stop_line("l", close=close)
    assert runtime.runners == {"l": line}  # the running load, until the next is swapped in
    gone = runtime.submit("d", None, JobKind.READ, ParameterDescription())  # type: ignore[arg-type]
    assert len(line.jobs) == 1 and isinstance(gone.result().outcome, Cancelled)
    await runtime.stop()
    await runtime.stop()
    assert (closed, cleaned) == ([1], [1])
