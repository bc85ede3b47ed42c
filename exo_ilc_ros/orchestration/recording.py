"""The bag recorder of ``exo-ilc run``: in the supervisor's process (default) or its own.

In the supervisor's process (``nodes/container.py``) the recorder shares the supervisor's DDS
participant and its /joint_states subscription (:class:`~exo_ilc_ros.nodes.common.Inbox`), so
the control loop's samples reach one process fewer; a recorder process of its own
(``isolated``) costs the lock-step loop two to three times as much (``bench/bag_bench.py``) but
survives the supervisor and vice versa.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from types import TracebackType

import yaml

from ..bag.run_writer import run_name, unique_path
from ..core.params import schema
from ..core.params.config import Config
from ..nodes.registry import RECORDER
from ..wire.relay import DISPLAY_RATE
from .launcher import GRAPH_NODES, NodeSpec, composed

RECORDER_MODULE = RECORDER.module


class Recording:
    """Where a graph run's bag goes and the recorder's process spec; a context manager that
    keeps the run's effective config in a file the recorder copies into the bag."""

    def __init__(self, config: Config, bag_dir: Path | str = "bags", name: str = "",
                 split_every: int = 1, relay: Path | None = None,
                 relay_rate: float = DISPLAY_RATE) -> None:
        self.config = config
        self.relay = relay
        self.relay_rate = relay_rate
        """The live view's display rate (:class:`~exo_ilc_ros.wire.relay.SampleGate`)."""
        """Where the live view listens for the recorder's feed (:attr:`.live.LiveView.relay`)."""
        self.name = name or run_name("graph", config["law"], config["mass_uncertainty"])
        self.path = unique_path(bag_dir, self.name).resolve()
        self.split_every = split_every
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self.config_file: Path | None = None
        self.params_file: Path | None = None
        """The recorder's own parameters (a params file: in a container, ``-p`` would reach
        every node of the process)."""

    def __enter__(self) -> Recording:
        self._tmp = tempfile.TemporaryDirectory(prefix="exo_ilc_bag_")
        self.config_file = Path(self._tmp.name) / "effective.yaml"
        self.config_file.write_text(self.config.to_ros_yaml(f"run {self.name}"))
        self.params_file = Path(self._tmp.name) / f"{RECORDER.name}.yaml"
        self.params_file.write_text(yaml.safe_dump({RECORDER.name: {"ros__parameters": {
            "bag_path": str(self.path), "run_name": self.name,
            "config_file": str(self.config_file), "split_every": self.split_every,
            **({"relay": str(self.relay), "relay_rate": float(self.relay_rate)}
               if self.relay else {})}}}))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 trace: TracebackType | None) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    @property
    def spec(self) -> NodeSpec:
        """The recorder as a process of its own (``run_graph(..., extra=[recording.spec])``)."""
        if self.params_file is None:
            raise RuntimeError("Recording.spec outside its with-block")
        return NodeSpec(RECORDER.name, RECORDER_MODULE, ("--params-file", str(self.params_file)))

    def graph_nodes(self, isolated: bool = False,
                    nodes: tuple[NodeSpec, ...] = GRAPH_NODES) -> list[NodeSpec]:
        """The graph's processes with the recorder: in the supervisor's process, or
        (``isolated``) one more process (``run_graph(..., nodes=recording.graph_nodes())``)."""
        if isolated:
            return [*nodes, self.spec]
        return [composed([node, self.spec]) if node.name == schema.SUPERVISOR else node
                for node in nodes]
