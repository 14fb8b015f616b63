"""The package boundaries of DESIGN.md, checked on the source: who may import whom, and no
circles between modules (counting imports inside functions too)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("controller", "fmu", "scenarios", "bridge")
MAY_IMPORT = {  # DESIGN.md, "Layout and data flow"
    "controller": set(),
    "fmu": {"controller"},
    "scenarios": {"controller", "fmu"},
    "bridge": {"controller", "fmu", "scenarios"},
}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Every module of ours that `path` imports, at any depth of the code."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.add(target)
            found.update(f"{target}.{a.name}" for a in node.names)
    return {m for m in found if m.split(".")[0] in PACKAGES}


def _graph() -> dict[str, set[str]]:
    files = [p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")]
    modules = {_module_name(p): p for p in files}
    return {m: {t for t in _imports(p) if t in modules and t != m} for m, p in modules.items()}


def test_each_package_imports_only_what_the_design_allows():
    bad = [f"{m} imports {t}" for m, targets in _graph().items() for t in targets
           if t.split(".")[0] != m.split(".")[0]
           and t.split(".")[0] not in MAY_IMPORT[m.split(".")[0]]]
    assert not bad, bad


def test_nothing_imports_bridge_but_its_entry_points():
    bad = [f"{m} imports {t}" for m, targets in _graph().items() for t in targets
           if t.startswith("bridge") and not m.startswith("bridge")]
    assert not bad, bad


def test_no_module_imports_itself_through_others():
    graph = _graph()
    # a package's __init__ that re-exports its own modules is not a circle of modules
    edges = {m: {t for t in ts if not (graph.get(t) is not None and m.startswith(t + "."))}
             for m, ts in graph.items()}
    circles, state = [], {}

    def visit(m, stack):
        state[m] = 1
        stack.append(m)
        for t in sorted(edges[m]):
            if state.get(t) == 1:
                circles.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t, stack)
        stack.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m, [])
    assert not circles, [" -> ".join(c) for c in circles]


BRIDGE_ROOMS = {  # bridge/__init__.py: the rooms of `bridge` and which others each may import
    "bridge.shared": set(),
    "bridge.lidar": set(),
    "bridge.onboard": {"bridge.shared", "bridge.lidar"},
    "bridge.autopilot_sim": {"bridge.shared"},
    "bridge.sitl": {"bridge.shared"},
}
BRIDGE_EXCEPTIONS = {  # module -> the one further room it may import, and why
    "bridge.autopilot_sim.plant": "bridge.onboard",  # joins the boat side and the simulator
    "bridge.sitl.json_physics": "bridge.onboard",  # prints the `canalnav bridge` command line
}


def _room(module: str) -> str | None:
    return next((r for r in BRIDGE_ROOMS if module == r or module.startswith(r + ".")), None)


def test_every_bridge_module_lives_in_a_room_or_is_the_command_line():
    loose = [m for m in _graph() if m.startswith("bridge.") and _room(m) is None
             and m != "bridge.main" and not m.startswith("bridge.commands")]
    assert not loose, loose


def test_bridge_rooms_import_only_what_they_may():
    """The boat side never imports a simulator; the shared room imports no other room."""
    bad = []
    for m, targets in _graph().items():
        room = _room(m)
        if room is None:
            continue
        for t in targets:
            other = _room(t)
            if (other not in (None, room) and other not in BRIDGE_ROOMS[room]
                    and BRIDGE_EXCEPTIONS.get(m) != other):
                bad.append(f"{m} imports {t}")
    assert not bad, bad


def test_only_the_command_line_imports_the_command_line():
    bad = [f"{m} imports {t}" for m, targets in _graph().items() for t in targets
           if (t == "bridge.main" or t.startswith("bridge.commands"))
           and not (m == "bridge.main" or m.startswith("bridge.commands"))]
    assert not bad, bad
