"""Every module of pkwbus says what it offers: ``__all__``, each name of it defined."""

from __future__ import annotations

import ast
import importlib
import pathlib

import pytest

import pkwbus

ROOT = pathlib.Path(pkwbus.__file__).parent
PATHS = sorted(ROOT.rglob("*.py"))


def module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def declared(path: pathlib.Path) -> list[str] | None:
    """The names of the module's top-level ``__all__``, None when it has none."""
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        targets = node.targets if isinstance(node, ast.Assign) else []
        if isinstance(node, ast.AnnAssign):
            targets = [node.target]
        if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
            value = node.value
            assert isinstance(value, ast.List | ast.Tuple), f"{path}: __all__ is not a list"
            names = [ast.literal_eval(e) for e in value.elts]
            assert all(isinstance(n, str) for n in names), f"{path}: __all__ holds non-strings"
            return names
    return None


def test_the_walk_finds_the_modules() -> None:
    assert len(PATHS) > 100
    assert ROOT / "service" / "runtime.py" in PATHS


@pytest.mark.parametrize("path", PATHS, ids=lambda p: module_name(p))
def test_each_module_declares_all_and_defines_its_names(path: pathlib.Path) -> None:
    names = declared(path)
    assert names is not None, f"{module_name(path)} has no __all__"
    assert len(names) == len(set(names)), f"{module_name(path)}: a name is in __all__ twice"
    if path.name == "__main__.py":  # importing it would run the command
        assert names == []
        return
    module = importlib.import_module(module_name(path))
    missing = [name for name in names if not hasattr(module, name)]
    assert not missing, f"{module_name(path)}.__all__ names what it lacks: {missing}"


def test_modules_import_from_each_other_only_what_they_offer() -> None:
    """A name one pkwbus module imports from another is in that one's ``__all__``
    (or is a submodule): nothing private leaks between modules."""
    offered = {module_name(path): declared(path) or [] for path in PATHS}
    leaks = []
    for path in PATHS:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom) or node.level or node.module not in offered:
                continue
            for alias in node.names:
                submodule = f"{node.module}.{alias.name}"
                if alias.name not in offered[node.module] and submodule not in offered:
                    leaks.append(f"{module_name(path)}: {alias.name} from {node.module}")
    assert not leaks


MAX_LINES = 400


def test_no_module_is_longer_than_the_limit() -> None:
    long = {
        module_name(path): lines
        for path in PATHS
        if (lines := len(path.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }
    assert not long, f"modules over {MAX_LINES} lines: {long}"


# Exceptions that are not errors: control flow inside one module, never raised to a caller.
NOT_ERRORS = {"pkwbus.service.http.body_limit._TooLarge"}


def test_every_exception_of_pkwbus_has_the_one_root() -> None:
    """A caller tells pkwbus's own errors (a message for people) from a bug by one class."""
    from pkwbus.errors import PkwbusError

    found = []
    for path in PATHS:
        if path.name == "__main__.py":
            continue  # runs the command line
        module = importlib.import_module(module_name(path))
        for name, value in vars(module).items():
            if (
                isinstance(value, type)
                and issubclass(value, BaseException)
                and value.__module__ == module.__name__
            ):
                found.append(value)
                if f"{value.__module__}.{name}" not in NOT_ERRORS:
                    assert issubclass(value, PkwbusError), f"{value.__module__}.{name}"
    assert len(found) > 20  # the walk saw them


MAX_ROOM = 16  # modules in one folder: beyond it, the folder hides rooms of its own


def test_no_folder_holds_more_than_a_room_can() -> None:
    rooms: dict[pathlib.Path, int] = {}
    for path in PATHS:
        rooms[path.parent] = rooms.get(path.parent, 0) + 1
    crowded = {str(p.relative_to(ROOT)): n for p, n in rooms.items() if n > MAX_ROOM}
    assert not crowded, f"folders over {MAX_ROOM} modules: {crowded}"
    assert max(rooms.values()) > 5  # the count sees the folders
