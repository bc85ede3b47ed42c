"""The bag recorder as one more process of ``exo-ilc run`` (a :class:`launcher.NodeSpec`)."""

from __future__ import annotations

import tempfile
from pathlib import Path
from types import TracebackType

from ..core.config import Config
from ..launcher import NodeSpec
from .run_writer import run_name, unique_path

RECORDER_MODULE = "exo_ilc_ros.nodes.bag_recorder"


class Recording:
    """Where a graph run's bag goes and the recorder's process spec; a context manager that
    keeps the run's effective config in a file the recorder copies into the bag."""

    def __init__(self, config: Config, bag_dir: Path | str = "bags", name: str = "",
                 split_every: int = 1) -> None:
        self.config = config
        self.name = name or run_name("graph", config["law"], config["mass_uncertainty"])
        self.path = unique_path(bag_dir, self.name).resolve()
        self.split_every = split_every
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self.config_file: Path | None = None

    def __enter__(self) -> Recording:
        self._tmp = tempfile.TemporaryDirectory(prefix="exo_ilc_bag_")
        self.config_file = Path(self._tmp.name) / "effective.yaml"
        self.config_file.write_text(self.config.to_ros_yaml(f"run {self.name}"))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 trace: TracebackType | None) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    @property
    def spec(self) -> NodeSpec:
        """The recorder process (for ``run_graph(..., extra=[recording.spec])``)."""
        if self.config_file is None:
            raise RuntimeError("Recording.spec outside its with-block")
        return NodeSpec("bag_recorder", RECORDER_MODULE, (
            "-p", f"bag_path:={self.path}", "-p", f"run_name:={self.name}",
            "-p", f"config_file:={self.config_file}", "-p", f"split_every:={self.split_every}"))
