"""The package's modules import each other without a cycle (counting imports inside
functions, which only hide one), and in-process tuning loads no bag reader."""

import ast
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "ato_nodes"


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(source: str, name: str, is_package: bool, modules: set[str]) -> set[str]:
    """The `modules` that module `name` imports, at any level of its code. `from X
    import Y` counts as an import of X.Y when that is a module, else of X; the parent
    packages an import initialises on the way are not counted (every submodule would
    otherwise import its package)."""
    package = name if is_package else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(source, name)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            found.update(f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base
                         for alias in node.names)
    return {module for module in found if module in modules and module != name}


def import_graph() -> dict[str, set[str]]:
    paths = sorted(PACKAGE.rglob("*.py"))
    modules = {module_name(path) for path in paths}
    return {module_name(path): imported_modules(path.read_text(), module_name(path),
                                                path.name == "__init__.py", modules)
            for path in paths}


def find_cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle as the modules along it (first repeated at the end), or []."""
    state: dict[str, str] = {}  # "open" while on the path, "done" after
    path: list[str] = []

    def visit(module: str) -> list[str]:
        state[module] = "open"
        path.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == "open":
                return path[path.index(target):] + [target]
            if target not in state:
                cycle = visit(target)
                if cycle:
                    return cycle
        path.pop()
        state[module] = "done"
        return []

    for module in sorted(graph):
        if module not in state:
            cycle = visit(module)
            if cycle:
                return cycle
    return []


def test_the_graph_sees_every_kind_of_import():
    modules = {"p", "p.a", "p.b", "p.c", "p.d", "p.sub", "p.sub.e"}
    source = ("import p.a\nfrom .. import b\nfrom . import e, NAME\n"
              "def f():\n    from ..c import thing\n    import p.d as d\n")
    assert imported_modules(source, "p.sub.m", False, modules) == {
        "p.a", "p.b", "p.sub", "p.sub.e", "p.c", "p.d"}
    assert imported_modules("from . import e", "p.sub", True, modules) == {"p.sub.e"}
    graph = import_graph()
    assert "ato_nodes.core.config.schema" in graph["ato_nodes.core.run.loop"]
    assert "ato_nodes.results.jsontext" in graph["ato_nodes.reports.report"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) == []


def test_the_package_has_no_import_cycle():
    cycle = find_cycle(import_graph())
    assert not cycle, " -> ".join(cycle)


def test_in_process_tuning_does_not_load_the_bag_reader():
    code = ("import ato_nodes.studies.tuning, sys; "
            "assert 'rosbags' not in sys.modules, 'rosbags loaded'")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr


# The rooms of ato_nodes/core and the rooms each may import besides itself, from the
# bottom up (docs/architecture.md): configuration names the kinds, so it sits on the
# algorithms it assembles; the run (stages, loops, the scorer of a run) on everything.
ROOMS_BELOW = {
    "base": set(),
    "optimizers": {"base"},
    "train": {"base"},
    "scoring": {"base"},
    "control": {"base", "optimizers", "train"},
    "targets": {"base", "optimizers", "train"},
    "config": {"base", "optimizers", "train", "scoring", "control", "targets"},
    "run": {"base", "optimizers", "train", "scoring", "control", "targets", "config"},
}
OUTSIDE_THE_CORE = ("rclpy", "rosbags", "mcap", "std_msgs", "geometry_msgs", "rosgraph_msgs")


def room(module: str) -> str | None:
    """The room of a core module (or of a room's package itself), else None."""
    parts = module.split(".")
    return parts[2] if len(parts) > 2 and parts[:2] == ["ato_nodes", "core"] else None


def test_every_core_module_sits_in_a_room_and_imports_only_the_rooms_below_it():
    graph = import_graph()
    core = [m for m in graph if room(m) is not None]
    assert {room(m) for m in core} == set(ROOMS_BELOW), "a module outside the rooms"
    wrong = [f"{m} imports {t}" for m in core for t in graph[m]
             if room(t) != room(m) and room(t) not in ROOMS_BELOW[room(m)]]
    assert not wrong, "; ".join(wrong)


def test_the_core_knows_nothing_of_ros_bags_or_the_rest_of_the_package():
    for path in sorted((PACKAGE / "core").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom)
                     and not node.level else [])
            for name in names:
                assert not name.startswith(OUTSIDE_THE_CORE), f"{path} imports {name}"
                assert not name.startswith("ato_nodes.") or name.startswith("ato_nodes.core"), \
                    f"{path} imports {name}"
            if isinstance(node, ast.ImportFrom) and node.level:
                depth = len(path.relative_to(PACKAGE / "core").parts) - 1
                assert node.level <= depth + 1, f"{path} imports from beyond the core"


# The package's rooms (ato_nodes/<room>/) and the rooms each may import besides itself,
# from the bottom up (docs/architecture.md). The nodes and the launcher stand side by side:
# the launcher starts the nodes by name in another process and imports none of them.
PACKAGE_ROOMS_BELOW = {
    "core": set(),
    "results": {"core"},
    "api": {"core", "results"},
    "plugin": {"core"},
    "bags": {"core", "results"},
    "reports": {"core", "results", "bags"},
    "launcher": {"core", "results", "bags"},
    "nodes": {"core", "results", "bags"},
    "studies": {"core", "results", "bags", "reports", "launcher"},
    "cli": {"core", "results", "bags", "reports", "launcher", "nodes", "studies"},
}


def package_room(module: str) -> str | None:
    """The room of a module of the package (ato_nodes.<room>...), None for the package."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def test_the_rooms_rules_have_no_cycle():
    assert not find_cycle(ROOMS_BELOW)
    assert not find_cycle(PACKAGE_ROOMS_BELOW)


def test_every_module_of_the_package_sits_in_a_room_and_imports_only_the_rooms_below_it():
    graph = import_graph()
    assert {package_room(m) for m in graph} - {None} == set(PACKAGE_ROOMS_BELOW), \
        "a module outside the rooms"
    wrong = [f"{m} imports {t}" for m in graph for t in graph[m]
             if package_room(m) is not None and package_room(t) != package_room(m)
             and package_room(t) not in PACKAGE_ROOMS_BELOW[package_room(m)]]
    assert not wrong, "; ".join(wrong)
