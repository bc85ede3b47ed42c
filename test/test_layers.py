"""The house's layers: each package imports only the ones below it, and the ROS-free ones never
import rclpy (core, wire, bag and analysis run where no ROS is installed)."""

from __future__ import annotations

import ast
from pathlib import Path

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


def _imports(path: Path) -> list[tuple[str, int]]:
    """(absolute module, line) of every import in ``path``, lazy ones included."""
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    package = parts[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                out.append((".".join(base + ([node.module] if node.module else [])),
                            node.lineno))
            else:
                out.append((node.module or "", node.lineno))
        elif isinstance(node, ast.Import):
            out += [(alias.name, node.lineno) for alias in node.names]
    return out


def test_every_module_lives_in_a_layer() -> None:
    loose = sorted(p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    assert loose == [], f"modules outside the layer packages: {loose}"
    assert {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()} == set(ALLOWED)


def test_no_layer_imports_a_higher_one() -> None:
    wrong = []
    for layer, allowed in ALLOWED.items():
        for path in sorted((PACKAGE / layer).rglob("*.py")):
            for module, line in _imports(path):
                names = module.split(".")
                if names[0] != "exo_ilc_ros" or len(names) < 2:
                    continue
                if names[1] != layer and names[1] not in allowed:
                    wrong.append(f"{path.relative_to(PACKAGE)}:{line} imports {module}")
    assert wrong == [], "\n".join(wrong)


def test_ros_free_layers_never_import_rclpy() -> None:
    ros = ("rclpy", "rosidl_runtime_py", "sensor_msgs", "std_msgs", "diagnostic_msgs",
           "trajectory_msgs", "builtin_interfaces", "rcl_interfaces", "std_srvs")
    wrong = [f"{path.relative_to(PACKAGE)}:{line} imports {module}"
             for layer in ROS_FREE for path in sorted((PACKAGE / layer).rglob("*.py"))
             for module, line in _imports(path) if module.split(".")[0] in ros]
    assert wrong == [], "\n".join(wrong)
