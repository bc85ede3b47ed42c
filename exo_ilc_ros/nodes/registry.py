"""The package's nodes, in one list: what setup.py installs as executables, what the launch file
and ``exo-ilc run`` start, and what a container can build.

Plain data with no import of the package, so setup.py reads it at build time
(``runpy.run_path``) without importing rclpy or numba.
"""

from __future__ import annotations

from typing import NamedTuple


class NodeEntry(NamedTuple):
    """One node of the package."""

    name: str
    """Node name, executable name (``ros2 run exo_ilc_ros <name>``) and parameter section."""
    module: str
    """The module with the node's class and its ``main``."""
    cls: str
    """The node class (what a container builds)."""

    @property
    def entry_point(self) -> str:
        """``module:main``, the executable's entry point."""
        return f"{self.module}:main"

    @property
    def factory(self) -> str:
        """``module:Class``, what a container imports."""
        return f"{self.module}:{self.cls}"


PLANT = NodeEntry("plant_simulator", "exo_ilc_ros.nodes.plant_simulator", "PlantSimulator")
CONTROLLER = NodeEntry("computed_torque_controller",
                       "exo_ilc_ros.nodes.computed_torque_controller", "ComputedTorqueController")
SUPERVISOR = NodeEntry("ilc_supervisor", "exo_ilc_ros.nodes.ilc_supervisor", "IlcSupervisor")
RECORDER = NodeEntry("bag_recorder", "exo_ilc_ros.nodes.bag_recorder", "BagRecorder")
MUJOCO_PLANT = NodeEntry("mujoco_plant", "exo_ilc_ros.nodes.mujoco_plant", "MujocoPlant")
"""The arm in MuJoCo, no services (``protocol: homing``); its ROS node name is the plant's
(``plant_simulator``: the same parameters), so it replaces PLANT in a graph."""
FREE_RUNNING_PLANT = NodeEntry("free_running_plant", "exo_ilc_ros.nodes.free_running_plant",
                               "FreeRunningPlant")
"""Our simulator without services (``protocol: homing``); node name ``plant_simulator`` too."""
PLANTS: dict[str, NodeEntry] = {"simulator": PLANT, "mujoco": MUJOCO_PLANT,
                                "simulator_homing": FREE_RUNNING_PLANT}
"""The plant a graph runs (``exo-ilc run --plant``, the launch file's ``plant:=``); with
``protocol: homing`` the simulator runs as ``free_running_plant``."""

BRIDGE = NodeEntry("foxglove_bridge", "exo_ilc_ros.nodes.foxglove_bridge", "FoxgloveBridge")
"""The live view: the graph over the Foxglove WebSocket protocol (``exo-ilc run --live``);
always a process of its own, beside the graph."""

NODES: tuple[NodeEntry, ...] = (PLANT, CONTROLLER, SUPERVISOR, RECORDER, MUJOCO_PLANT,
                                FREE_RUNNING_PLANT, BRIDGE)
"""Every node of the package."""
GRAPH: tuple[NodeEntry, ...] = (PLANT, CONTROLLER, SUPERVISOR)
"""The control graph, in start order; the recorder comes beside it (its own process, or in
the supervisor's: ``exo-ilc run``)."""

CONTAINER_MODULE = "exo_ilc_ros.nodes.container"
"""The executable that runs several nodes in one process (``container NODE ...``)."""


def console_scripts() -> list[str]:
    """setup.py's ``console_scripts`` for the nodes and the container: ``name = module:main``."""
    return [f"{node.name} = {node.entry_point}" for node in NODES] + \
        [f"container = {CONTAINER_MODULE}:main"]
