"""The house's layers: each package imports only the ones below it, core's rooms only the rooms
below them, no module imports another in a circle, no module of the package is imported inside a
function, and the ROS-free layers never import rclpy (core, wire, bag and analysis run where no
ROS is installed)."""

from __future__ import annotations

import ast
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

from exo_ilc_ros.core import ROOMS

PACKAGE = Path(__file__).resolve().parents[1] / "exo_ilc_ros"
ALLOWED = {
    "core": set(),
    "wire": set(),
    "bag": {"core", "wire"},
    "analysis": {"core", "wire", "bag"},
    "nodes": {"core", "wire", "bag"},
    "orchestration": {"core", "wire", "bag", "nodes"},
    "cli": {"core", "wire", "bag", "analysis", "nodes", "orchestration"},
}
"""Package -> the packages it may import (bottom: core, the paper's mathematics; wire, the
message contract; top: cli, the exo-ilc command)."""
ROS_FREE = ("core", "wire", "bag", "analysis")
CORE_SHARED = {"errors", "_numba_cache"}
"""core's loose modules every room may import (besides the face, ``core/__init__.py``)."""


def _module(path: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        return ".".join(parts[:-1]), True
    return ".".join(parts), False


def _imports(path: Path) -> list[tuple[str, int, bool]]:
    """(absolute module, line, inside a function) of every import in ``path``; ``from X import
    name`` gives ``X.name`` (a module or not: callers trim to what exists)."""
    name, is_package = _module(path)
    package = name.split(".") if is_package else name.split(".")[:-1]
    tree = ast.parse(path.read_text())
    in_function = {id(node) for func in ast.walk(tree)
                   if isinstance(func, ast.FunctionDef | ast.AsyncFunctionDef)
                   for node in ast.walk(func) if node is not func}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1])
                module = base + ("." + node.module if node.module else "")
            else:
                module = node.module or ""
            out += [(f"{module}.{alias.name}", node.lineno, id(node) in in_function)
                    for alias in node.names]
        elif isinstance(node, ast.Import):
            out += [(alias.name, node.lineno, id(node) in in_function) for alias in node.names]
    return out


def _modules() -> dict[str, Path]:
    return {_module(p)[0]: p for p in sorted(PACKAGE.rglob("*.py"))}


def _owner(name: str, modules: dict[str, Path]) -> str | None:
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def _graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (a package's ``__init__`` importing its own
    children is not an edge of the package)."""
    modules = _modules()
    edges: dict[str, set[str]] = defaultdict(set)
    for name, path in modules.items():
        for target, _, _ in _imports(path):
            owner = _owner(target, modules)
            if owner and owner != name and not owner.startswith(name + "."):
                edges[name].add(owner)
    return edges


def test_every_module_lives_in_a_layer() -> None:
    loose = sorted(p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    assert loose == [], f"modules outside the layer packages: {loose}"
    assert {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()} == set(ALLOWED)


def test_core_has_rooms_and_only_its_shared_modules_loose() -> None:
    loose = {p.stem for p in (PACKAGE / "core").glob("*.py")} - {"__init__"}
    assert loose == CORE_SHARED
    rooms = {p.name for p in (PACKAGE / "core").iterdir() if (p / "__init__.py").exists()}
    assert rooms == set(ROOMS)


def test_no_layer_imports_a_higher_one() -> None:
    wrong = []
    for layer, allowed in ALLOWED.items():
        for path in sorted((PACKAGE / layer).rglob("*.py")):
            for module, line, _ in _imports(path):
                names = module.split(".")
                if names[0] != "exo_ilc_ros" or len(names) < 3:
                    continue
                if names[1] != layer and names[1] not in allowed:
                    wrong.append(f"{path.relative_to(PACKAGE)}:{line} imports {module}")
    assert wrong == [], "\n".join(wrong)


def test_no_core_room_imports_a_higher_one() -> None:
    rank = {room: i for i, room in enumerate(ROOMS)}
    modules = _modules()
    wrong = []
    for room in ROOMS:
        for path in sorted((PACKAGE / "core" / room).rglob("*.py")):
            for module, line, _ in _imports(path):
                owner = _owner(module, modules) or ""
                names = owner.split(".")
                if names[:2] != ["exo_ilc_ros", "core"] or len(names) < 3:
                    continue
                if names[2] in CORE_SHARED:
                    continue
                if names[2] not in rank or rank[names[2]] > rank[room]:
                    wrong.append(f"core/{room}/{path.name}:{line} imports {owner}")
    assert wrong == [], "\n".join(wrong)


def test_no_import_cycle() -> None:
    edges = _graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in sorted(_modules()):
        if module not in index:
            visit(module)
    assert cycles == [], "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_no_own_module_imported_inside_a_function() -> None:
    """Except a command of ``cli`` importing a lower layer where it runs (its experiment,
    analysis, optuna ...): the parser is built without them, so ``exo-ilc --help`` answers at
    once (test_cli_startup.py). A lower layer never imports cli, so this hides no cycle."""
    modules = _modules()
    cli = PACKAGE / "cli"
    lazy = [f"{path.relative_to(PACKAGE)}:{line} imports {module}"
            for path in modules.values() for module, line, inside in _imports(path)
            if inside and (owner := _owner(module, modules))
            and not (path.parent == cli and not owner.startswith("exo_ilc_ros.cli"))]
    assert lazy == [], "\n".join(lazy)


def test_ros_free_layers_never_import_rclpy() -> None:
    ros = ("rclpy", "rosidl_runtime_py", "sensor_msgs", "std_msgs", "diagnostic_msgs",
           "trajectory_msgs", "builtin_interfaces", "rcl_interfaces", "std_srvs")
    wrong = [f"{path.relative_to(PACKAGE)}:{line} imports {module}"
             for layer in ROS_FREE for path in sorted((PACKAGE / layer).rglob("*.py"))
             for module, line, _ in _imports(path) if module.split(".")[0] in ros]
    assert wrong == [], "\n".join(wrong)


def test_light_faces_load_neither_numba_nor_rclpy() -> None:
    """Reading a bag or importing the core's face compiles nothing and starts no ROS."""
    code = ("import sys, exo_ilc_ros.core, exo_ilc_ros.bag, exo_ilc_ros.analysis; "
            "heavy = [m for m in ('numba', 'rclpy') if m in sys.modules]; "
            "assert not heavy, heavy; "
            "from exo_ilc_ros.core import run_trials, Config; print('ok')")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr
