"""Packaging: package.xml declares what setup.py installs (so `rosdep install` gives a working
package on a ROS machine)."""

from __future__ import annotations

import ast
import re
import runpy
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import setuptools

ROOT = Path(__file__).resolve().parents[1]

ROSDEP_KEYS: dict[str, str] = {
    "setuptools": "python3-setuptools",
    "numpy": "python3-numpy",
    "numba": "python3-numba",
    "scipy": "python3-scipy",
    "pyyaml": "python3-yaml",
    "tqdm": "python3-tqdm",
    "matplotlib": "python3-matplotlib",
    "rosbags": "python3-rosbags-pip",
    "mcap": "python3-mcap-pip",
    "mcap-ros2-support": "mcap-ros2-support",
    "optuna": "python3-optuna-pip",
    "cmaes": "python3-cmaes-pip",
    "clarabel": "python3-clarabel-pip",
    "mujoco": "python3-mujoco-pip",
    "myo-sim": "python3-myo-sim-pip",
    "distributed": "python3-distributed",
    "foxglove-sdk": "python3-foxglove-sdk-pip",
}
"""pip name -> rosdep key (rosdistro's rosdep/python.yaml: the system package where there is
one, a ``-pip`` key otherwise; ``mcap-ros2-support`` is that key's own name there)."""
ROS_PREFIX = "ros-jazzy-"
"""A ROS package's wheel: ``ros-jazzy-sensor-msgs`` -> the package ``sensor_msgs``."""
ROS_EXTRAS: dict[str, str] = {"fastrtps": "rmw_fastrtps_cpp"}
"""Extras of the ROS wheels -> the ROS package they pull in."""


def setup_arguments() -> dict[str, Any]:
    """The keyword arguments setup.py passes to ``setuptools.setup`` (run, not parsed)."""
    captured: dict[str, Any] = {}
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(setuptools, "setup", lambda **kwargs: captured.update(kwargs))
        patch.chdir(ROOT)
        runpy.run_path(str(ROOT / "setup.py"), run_name="__main__")
    return captured


def rosdep_keys(requirement: str) -> list[str]:
    """The rosdep keys that install one ``install_requires`` entry."""
    match = re.fullmatch(r"([A-Za-z0-9_.-]+)(?:\[([^\]]*)\])?\s*(?:[<>=!~].*)?", requirement)
    assert match, f"cannot parse the requirement {requirement!r}"
    name = match.group(1).lower().replace("_", "-")
    extras = [e.strip() for e in (match.group(2) or "").split(",") if e.strip()]
    if name.startswith(ROS_PREFIX):
        keys = [name[len(ROS_PREFIX):].replace("-", "_")]
    else:
        assert name in ROSDEP_KEYS, (f"setup.py requires {name!r}: add its rosdep key to "
                                     "ROSDEP_KEYS here and an <exec_depend> to package.xml")
        keys = [ROSDEP_KEYS[name]]
    for extra in extras:
        assert extra in ROS_EXTRAS, f"{requirement}: add the extra {extra!r} to ROS_EXTRAS"
        keys.append(ROS_EXTRAS[extra])
    return keys


def declared_run_dependencies() -> set[str]:
    """``<exec_depend>`` and ``<depend>`` keys of package.xml."""
    root = ET.parse(ROOT / "package.xml").getroot()
    return {e.text.strip() for tag in ("exec_depend", "depend") for e in root.iter(tag)
            if e.text}


def test_package_xml_declares_every_install_requirement() -> None:
    requires = setup_arguments()["install_requires"]
    assert "numba>=0.60" in requires  # really read setup.py's list
    declared = declared_run_dependencies()
    missing = {(r, k) for r in requires for k in rosdep_keys(r) if k not in declared}
    assert not missing, f"package.xml lacks <exec_depend> for {sorted(missing)}"


def test_the_shipped_rosdep_file_resolves_our_own_keys() -> None:
    """rosdep.yaml (for rosdep users whose rosdistro lacks a key) maps every ``-pip`` key and
    the others we declare beyond the common ones to the package setup.py requires."""
    import yaml

    rules = yaml.safe_load((ROOT / "rosdep.yaml").read_text())
    declared = declared_run_dependencies()
    own = {pip: key for pip, key in ROSDEP_KEYS.items()
           if key.endswith("-pip") or key in ("mcap-ros2-support", "python3-distributed")}
    assert "mujoco" in own and "distributed" in own
    for pip_name, key in own.items():
        assert key in declared and key in rules, key
        for system in ("ubuntu", "debian"):
            rule = rules[key][system]
            if isinstance(rule, dict):
                assert rule == {"pip": {"packages": [pip_name]}}, (key, rule)
            else:  # a system package of that library
                assert rule == [f"python3-{pip_name}"], (key, rule)


def test_package_xml_declares_the_launch_files_imports() -> None:
    declared = declared_run_dependencies()
    for launch_file in (ROOT / "launch").glob("*.py"):
        tree = ast.parse(launch_file.read_text())
        imported = {alias.name.split(".")[0] for node in ast.walk(tree)
                    if isinstance(node, ast.Import) for alias in node.names}
        imported |= {node.module.split(".")[0] for node in ast.walk(tree)
                     if isinstance(node, ast.ImportFrom) and node.module and not node.level}
        ros = imported - set(sys.stdlib_module_names) - {"exo_ilc_ros"}
        assert ros <= declared, f"{launch_file.name} imports {sorted(ros - declared)}"


DOCUMENTS = ("*.md", "docs/*.md", "bags/*.md", "config/*.yaml", "launch/*.py", "setup.py")
LINK = re.compile(r"\]\(([^)\s]+)\)")
UPWARD = re.compile(r"(?<![\w.])(\.\./[^\s`'\")\]]*)")


def test_links_stay_inside_the_repository() -> None:
    """Every relative Markdown link resolves to a file of the repository, and no path written
    with ``../`` leaves it (a reader of a clone or a copy has nothing else)."""
    root = ROOT.resolve()
    checked = 0
    for pattern in DOCUMENTS:
        for document in sorted(ROOT.glob(pattern)):
            text = document.read_text()
            for target in LINK.findall(text):
                if re.match(r"[a-z]+:", target) or target.startswith("#"):
                    continue
                path = (document.parent / target.split("#")[0]).resolve()
                assert path.is_relative_to(root) and path.exists(), \
                    f"{document.relative_to(ROOT)}: link {target} does not resolve in the repo"
                checked += 1
            for target in UPWARD.findall(text):
                path = (document.parent / target).resolve()
                assert path.is_relative_to(root), \
                    f"{document.relative_to(ROOT)}: {target} points outside the repository"
    assert checked >= 2  # README -> the docs pages and its figure at least


def test_the_package_ships_its_type_hints() -> None:
    """PEP 561: ``py.typed`` is in the package and installed with it."""
    assert (ROOT / "exo_ilc_ros" / "py.typed").is_file()
    assert "py.typed" in setup_arguments()["package_data"]["exo_ilc_ros"]


def test_setup_installs_the_registrys_executables() -> None:
    from exo_ilc_ros.nodes import registry

    scripts = setup_arguments()["entry_points"]["console_scripts"]
    assert scripts == ["exo-ilc = exo_ilc_ros.cli.main:main", *registry.console_scripts()]
    assert {s.split(" = ")[0] for s in scripts} >= {n.name for n in registry.NODES}


def test_one_node_registry() -> None:
    """The launcher, the container, the recorder's spec and the nodes' own names agree with
    the registry, and every registry entry points at a real node class and main."""
    import importlib

    from exo_ilc_ros.core.params import schema
    from exo_ilc_ros.nodes import container, registry
    from exo_ilc_ros.orchestration.launcher import GRAPH_NODES
    from exo_ilc_ros.orchestration.recording import RECORDER_MODULE

    assert [(s.name, s.module) for s in GRAPH_NODES] == \
        [(n.name, n.module) for n in registry.GRAPH]
    assert [n.name for n in registry.GRAPH] == [schema.PLANT, schema.CONTROLLER,
                                               schema.SUPERVISOR]
    assert {n.name: f"{n.module}:{n.cls}" for n in registry.NODES} == container.NODES
    assert registry.RECORDER.module == RECORDER_MODULE
    plants = set(registry.PLANTS.values())
    for node in registry.NODES:
        module = importlib.import_module(node.module)
        assert (schema.PLANT if node in plants else node.name) == module.NAME  # a plant's role
        assert callable(module.main) and isinstance(getattr(module, node.cls), type)


class _Stub:
    """Records the arguments it was built with (stands in for launch's classes)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args = args
        self.kwargs = kwargs


class _LaunchConfiguration:
    def __init__(self, name: str) -> None:
        self.name = name

    def perform(self, context: dict[str, str]) -> str:
        return context[self.name]


def _launched(monkeypatch: pytest.MonkeyPatch, **arguments: str) -> list[dict[str, Any]]:
    """The nodes the launch file starts with these launch arguments (launch and launch_ros
    stubbed: they are not on PyPI)."""
    import types

    import ament_index_python.packages

    contents: dict[str, dict[str, Any]] = {
        "launch": {"LaunchDescription": list},
        "launch.actions": {"DeclareLaunchArgument": _Stub, "OpaqueFunction": _Stub},
        "launch.launch_context": {"LaunchContext": dict},
        "launch.substitutions": {"LaunchConfiguration": _LaunchConfiguration},
        "launch_ros": {},
        "launch_ros.actions": {"Node": _Stub},
    }
    modules = {name: types.ModuleType(name) for name in contents}
    for name, module in modules.items():
        vars(module).update(contents[name])
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    monkeypatch.setattr(ament_index_python.packages, "get_package_share_directory",
                        lambda package: str(ROOT))
    launch_file = runpy.run_path(str(ROOT / "launch" / "exo_ilc.launch.py"))
    description = launch_file["generate_launch_description"]()
    context = {a.args[0]: a.kwargs["default_value"] for a in description if "default_value"
               in a.kwargs}
    assert set(arguments) <= set(context)
    context.update(arguments)
    (opaque,) = [a for a in description if "function" in a.kwargs]
    return [node.kwargs for node in opaque.kwargs["function"](context)]


def test_launch_file_starts_the_graph_and_the_recorder(monkeypatch: pytest.MonkeyPatch,
                                                       tmp_path: Path) -> None:
    from exo_ilc_ros.core.params.config import load_config
    from exo_ilc_ros.nodes import registry

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    nodes = _launched(monkeypatch, mass_uncertainty="0.1", bag_path=str(tmp_path / "bag"))
    assert [n["executable"] for n in nodes] == [n.name for n in (*registry.GRAPH,
                                                                 registry.RECORDER)]
    assert all(n["name"] == n["executable"] for n in nodes)
    assert nodes[0]["parameters"][-1] == {"mass_uncertainty": 0.1}
    assert nodes[1]["parameters"] == [str(ROOT / "config" / "exo_ilc.yaml")]
    (recorder,) = nodes[3]["parameters"]
    assert recorder["bag_path"] == str(tmp_path / "bag")
    assert load_config(recorder["config_file"])["mass_uncertainty"] == 0.1
    assert [n["executable"] for n in _launched(monkeypatch, record="false")] == \
        [n.name for n in registry.GRAPH]
    mujoco = _launched(monkeypatch, plant="mujoco", mass_uncertainty="0.1")
    assert [(n["executable"], n["name"]) for n in mujoco[:3]] == \
        [("mujoco_plant", "plant_simulator"), *((n.name, n.name) for n in registry.GRAPH[1:])]
    assert all({"protocol": "homing"} in n["parameters"] for n in mujoco[:3])
    assert load_config(mujoco[3]["parameters"][0]["config_file"])["protocol"] == "homing"
    live = _launched(monkeypatch, live="true", live_port="9001", mass_uncertainty="0.1")
    assert [n["executable"] for n in live] == [n.name for n in (
        *registry.GRAPH, registry.RECORDER, registry.BRIDGE)]
    (bridge,) = live[4]["parameters"]
    assert (bridge["host"], bridge["port"]) == ("127.0.0.1", 9001)  # this machine only
    assert load_config(bridge["config_file"])["mass_uncertainty"] == 0.1
    # the recorder feeds the view (one socket for both); without a recorder the view reads DDS
    assert bridge["relay"] and live[3]["parameters"][0]["relay"] == bridge["relay"]
    (alone,) = _launched(monkeypatch, live="true", record="false")[3]["parameters"]
    assert alone["relay"] == "" and recorder["relay"] == ""
