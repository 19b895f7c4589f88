"""The import graph of pkwbus: no cycle between modules, and the layers of
docs/architecture.md (``protocol`` below everything, only ``service`` and the
commands wire the layers together), and the order of the rooms of ``service``."""

from __future__ import annotations

import ast

from tests.test_modules import PATHS, module_name

MODULES = {module_name(path): path for path in PATHS}

# What each layer may import from the others (its own modules always).
MAY_IMPORT = {
    "protocol": {"errors"},
    "notation": {"errors"},
    "catalog": {"protocol", "notation", "errors"},
    # waiting: a timed wait that never loses a cancellation, under every layer like errors
    "link": {"protocol", "errors", "waiting"},
    # master knows neither HTTP nor the command line: their exit codes and answers
    # live with the commands and the service (commands.failures, service.writes.outcomes)
    "master": {"protocol", "catalog", "link", "errors", "waiting"},
    "sim": {"protocol", "catalog", "notation", "pkwbus", "errors"},
}


def imports(name: str, *, typing: bool = True) -> set[str]:
    """The pkwbus modules ``name`` imports: when it is loaded, and (``typing``) under
    ``TYPE_CHECKING`` too: a layer's types are a dependency like its code."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if not typing and isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            continue
        for n in ast.walk(node):
            if isinstance(n, ast.Import):
                found |= {a.name for a in n.names if a.name in MODULES}
            elif isinstance(n, ast.ImportFrom):
                if n.level:
                    base = package.split(".")[: len(package.split(".")) - (n.level - 1)]
                    module = ".".join([*base, *([n.module] if n.module else [])])
                else:
                    module = n.module or ""
                if module not in MODULES:
                    continue
                subs = {f"{module}.{a.name}" for a in n.names} & MODULES.keys()
                found |= subs
                if len(subs) < len(n.names):  # a name of the module itself
                    found.add(module)
    found.discard(name)
    return found


GRAPH = {name: imports(name) for name in MODULES}
LOADED = {name: imports(name, typing=False) for name in MODULES}


def layer(name: str) -> str:
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def test_the_graph_is_seen() -> None:
    assert "pkwbus.protocol.pkw" in GRAPH["pkwbus.master.planning.transaction"]
    assert "pkwbus.master.planning.planner" in GRAPH["pkwbus.master.runner"]
    assert LOADED.keys() == GRAPH.keys()


# What the planner may not know (docs/architecture.md, rule 2): which bus it serves. Its
# drives' carriers hide the bus; it never imports a bus, a carrier, a wire or a target.
NOT_FOR_PLANNING = (
    "pkwbus.protocol.profibus",
    "pkwbus.protocol.profidrive",
    "pkwbus.protocol.serial",
    "pkwbus.master.carriers",
    "pkwbus.master.wires",
    "pkwbus.master.target",
    "pkwbus.master.runner",
    "pkwbus.master.sessions",
    "pkwbus.master.snapshot_writer",
    "pkwbus.link.port",
)


def test_the_planner_does_not_know_the_bus() -> None:
    wrong = sorted(
        f"{name} imports {dep}"
        for name, deps in GRAPH.items()
        if name.startswith("pkwbus.master.planning")
        for dep in deps
        if dep.startswith(NOT_FOR_PLANNING)
    )
    assert not wrong
    planning = [n for n in GRAPH if n.startswith("pkwbus.master.planning.")]
    assert len(planning) >= 10


def test_the_planner_does_not_reach_the_bus_through_another_module() -> None:
    """Nor through what it imports: a job's result is a :class:`Reading` of
    ``master.reading``, not of the read model, which knows the DP slaves' states."""

    def reached(name: str, seen: set[str]) -> set[str]:
        for dep in GRAPH[name] - seen:
            seen.add(dep)
            reached(dep, seen)
        return seen

    wrong = sorted(
        f"{name} reaches {dep}"
        for name in GRAPH
        if name.startswith("pkwbus.master.planning")
        for dep in reached(name, set())
        if dep.startswith(NOT_FOR_PLANNING)
    )
    assert not wrong


def test_no_import_cycle() -> None:
    done: set[str] = set()
    path: list[str] = []

    def visit(name: str) -> None:
        path.append(name)
        for dep in sorted(GRAPH[name]):
            assert dep not in path, "import cycle: " + " -> ".join([*path[path.index(dep) :], dep])
            if dep not in done:
                visit(dep)
        path.pop()
        done.add(name)

    for name in sorted(GRAPH):
        if name not in done:
            visit(name)


def test_each_layer_imports_only_the_layers_below_it() -> None:
    wrong = sorted(
        f"{name} imports {dep}"
        for name, deps in GRAPH.items()
        if layer(name) in MAY_IMPORT
        for dep in deps
        if layer(dep) != layer(name) and layer(dep) not in MAY_IMPORT[layer(name)]
    )
    assert not wrong


# The rooms of service/, lowest first: each imports only rooms before it, and runtime.
SERVICE_ROOMS = [
    "config",
    "standby",
    "metrics",
    "audit",
    "history",
    "writes",
    "http",
    "mqtt",
    "assembly",
]


def service_room(name: str) -> str | None:
    parts = name.split(".")
    if parts[:2] != ["pkwbus", "service"] or len(parts) < 3:
        return None
    return parts[2]


def test_each_service_room_imports_only_the_rooms_below_it() -> None:
    """Every room may import the runtime and the roles it names (``roles``: what its parts
    are to it); the runtime imports only the roles, and the roles no room."""
    assert {service_room(n) for n in MODULES} - {None} == {*SERVICE_ROOMS, "runtime", "roles"}
    wrong = sorted(
        f"{name} imports {dep}"
        for name, deps in GRAPH.items()
        if (room := service_room(name)) in SERVICE_ROOMS
        for dep in deps
        if (other := service_room(dep)) not in (None, room, "runtime", "roles")
        and (other not in SERVICE_ROOMS[: SERVICE_ROOMS.index(room)])
    )
    assert not wrong
    assert not {service_room(dep) for dep in GRAPH["pkwbus.service.runtime"]} - {None, "roles"}
    assert not {service_room(dep) for dep in GRAPH["pkwbus.service.roles"]} - {None}


def test_nothing_in_master_prints() -> None:
    """master/ reports through events, logging and hooks; the commands print."""
    printing = sorted(
        name
        for name, path in MODULES.items()
        if layer(name) == "master"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.Call)
        and (
            (isinstance(node.func, ast.Name) and node.func.id == "print")
            or "sys.stderr" in ast.unparse(node)
            or "sys.stdout" in ast.unparse(node)
        )
    )
    assert not printing


# The command line hands over to the service here (`pkwbus run`), and nowhere else.
SERVICE_ENTRY = {("pkwbus.commands.service", "pkwbus.service.assembly.root")}


def test_the_commands_use_neither_the_api_nor_the_service_assembly() -> None:
    """A command shares the service's configuration, history and audit, never its HTTP
    layer or its composition root (what both need lives below them)."""
    wrong = sorted(
        f"{name} imports {dep}"
        for name, deps in GRAPH.items()
        if layer(name) == "commands"
        for dep in deps
        if dep.startswith(("pkwbus.service.http", "pkwbus.service.assembly"))
        and (name, dep) not in SERVICE_ENTRY
    )
    assert not wrong
    assert all(dep in GRAPH[name] for name, dep in SERVICE_ENTRY), "the entry is seen"


# What builds a request as it goes out: only master's carriers call these (the simulator
# builds its own answers), so that nothing shows bytes that are not the ones sent.
BUILDERS = {
    "pkwbus.protocol.serial.telegram": {"frame", "encode_block"},
    "pkwbus.protocol.pkw": {"encode_request"},
    "pkwbus.protocol.pkw.requests": {"encode_request"},
    "pkwbus.protocol.profibus.dp.ppo": {"encode_ppo_write"},
    "pkwbus.protocol.profidrive.pkw": {"record_request"},
}
BUILT_BY = ("pkwbus.master", "pkwbus.protocol", "pkwbus.sim")


def test_nothing_outside_master_builds_a_request() -> None:
    names = set().union(*BUILDERS.values())
    found = []
    for name, path in MODULES.items():
        if name.startswith(BUILT_BY):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module in BUILDERS:
                built = BUILDERS[node.module]
                found += [f"{name} imports {a.name}" for a in node.names if a.name in built]
            elif isinstance(node, ast.Attribute) and node.attr in names:
                found.append(f"{name} calls {ast.unparse(node)}")
    assert found == []


# The seam of a line (docs/architecture.md, rule 4): the runner is given its port and its
# wire apart, both typed by the line's requests and answers, and alone calls the port.
TYPED_SEAM = ("pkwbus.master.bus", "pkwbus.master.runner")
WIRES = (
    "pkwbus.master.wires.serial.wire",
    "pkwbus.master.wires.profibus.wire",
    "pkwbus.master.wires.profibus.live_list",
)


def _untyped(name: str) -> list[str]:
    """Where module ``name`` gives up a type: ``Any``, a ``cast``, a ``type: ignore``."""
    text = MODULES[name].read_text(encoding="utf-8")
    found = [f"{name}: type: ignore" for line in text.splitlines() if "type: ignore" in line]
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Name) and node.id in ("Any", "cast"):
            found.append(f"{name}:{node.lineno}: {node.id}")
        elif isinstance(node, ast.Attribute) and node.attr in ("Any", "cast"):
            found.append(f"{name}:{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.ImportFrom) and node.module == "typing":
            found += [f"{name}: imports {a.name}" for a in node.names if a.name in ("Any", "cast")]
    return found


def test_the_seam_of_port_wire_and_runner_is_typed() -> None:
    assert _untyped("pkwbus.master.sessions.session"), "the check sees an Any"
    assert not [found for name in TYPED_SEAM for found in _untyped(name)]


def test_a_wire_never_reaches_its_port() -> None:
    """A wire is given what it needs of its port when it is made (its answer timeout, the
    master's address); it imports no port, exposes none, and nobody but the runner goes
    through a wire to a port."""
    assert not [f"{w} imports {dep}" for w in WIRES for dep in GRAPH[w] if dep.endswith(".port")]
    exposing = sorted(
        f"{name}: {node.name}: {ast.unparse(item)}"
        for name in WIRES
        for node in ast.walk(ast.parse(MODULES[name].read_text(encoding="utf-8")))
        if isinstance(node, ast.ClassDef) and node.name.endswith("Wire")
        for item in ast.walk(node)
        if (isinstance(item, ast.FunctionDef) and item.name in ("port", "line"))
        or (
            isinstance(item, ast.Attribute)
            and item.attr in ("port", "line")
            and isinstance(item.value, ast.Name)
            and item.value.id == "self"
        )
    )
    assert not exposing
    through = sorted(
        f"{name}:{node.lineno}: {ast.unparse(node)}"
        for name, path in MODULES.items()
        if name != "pkwbus.master.runner"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.Attribute)
        and node.attr == "port"
        and (
            (isinstance(node.value, ast.Name) and node.value.id == "wire")
            or (isinstance(node.value, ast.Attribute) and node.value.attr == "wire")
        )
    )
    assert not through
