"""The live view of ``exo-ilc run --live``: ``foxglove_bridge`` as a process of its own beside
the graph (it must never share the control loop's processes), with the run's config, fed by
the run's recorder where there is one (``relayed``: no extra DDS reader of the loop's topics)."""

from __future__ import annotations

import socket
import tempfile
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType

from ..core.params.config import Config
from ..nodes.registry import BRIDGE
from ..wire.relay import DISPLAY_RATE
from .launcher import NodeSpec
from .live_layout import APPS, arm_layout, foxglove_json

DEFAULT_PORT = 8765
DEFAULT_HOST = "127.0.0.1"
READY_MARKER = '{"foxglove_port": '
"""What foxglove_bridge prints once it serves: the graph starts after it (``NodeSpec``)."""


def free_port(host: str) -> int:
    """A TCP port free on ``host`` now (the kernel's choice for port 0)."""
    try:
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
            probe.bind((host, 0))
            return int(probe.getsockname()[1])
    except OSError:  # an address we cannot bind: the bridge will say why
        return 0


class LiveView:
    """The bridge's process spec and the run's effective config file it reads (for the
    arm's URDF); a context manager that keeps that file while the graph runs."""

    def __init__(self, config: Config, port: int = DEFAULT_PORT,
                 host: str = DEFAULT_HOST, parameters: Mapping[str, str] | None = None,
                 relayed: bool = False, sample_rate: float = DISPLAY_RATE) -> None:
        self.config = config
        self.port = port if port else free_port(host)
        """The port it serves (0 asks for a free one, chosen here so :attr:`url` names it)."""
        self.host = host
        self.parameters = dict(parameters or {})
        """More of the bridge's parameters (``sample_reliability``, ``scheduling``, ...)."""
        self.sample_rate = sample_rate
        """The view's display rate (per-sample messages per second of wall time, 0: every
        one): the bridge's ``sample_rate``, or the recorder's ``relay_rate`` when relayed."""
        self.relayed = relayed
        """Fed by the run's recorder (:attr:`relay`) instead of reading DDS: give
        :attr:`relay` to the :class:`~.recording.Recording`."""
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self.config_file: Path | None = None
        self.relay: Path | None = None
        """The socket the bridge listens at for the recorder's feed (when :attr:`relayed`)."""
        self.layouts: dict[str, Path] = {}
        """App -> the layout made for this run's arm (``exo-ilc layout``), kept while the
        graph runs: import it in the app."""

    def __enter__(self) -> LiveView:
        self._tmp = tempfile.TemporaryDirectory(prefix="exo_ilc_live_")
        self.config_file = Path(self._tmp.name) / "effective.yaml"
        self.config_file.write_text(self.config.to_ros_yaml("run shown by foxglove_bridge"))
        if self.relayed:
            self.relay = Path(self._tmp.name) / "relay.sock"
        arm = arm_layout(self.config)
        for app in APPS:
            self.layouts[app] = Path(self._tmp.name) / f"{app}_layout.json"
            self.layouts[app].write_text(foxglove_json(arm, app))
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 trace: TracebackType | None) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    @property
    def url(self) -> str:
        """What to open in the Foxglove app."""
        return f"ws://{self.host}:{self.port}"

    @property
    def spec(self) -> NodeSpec:
        """``foxglove_bridge`` as one more process of the graph."""
        if self.config_file is None:
            raise RuntimeError("LiveView.spec outside its with-block")
        parameters = {"sample_rate": repr(float(self.sample_rate)), **self.parameters,
                      **({"relay": str(self.relay)} if self.relay else {})}
        more = tuple(arg for name, value in parameters.items()
                     for arg in ("-p", f"{name}:={value}"))
        return NodeSpec(BRIDGE.name, BRIDGE.module,
                        ("-p", f"host:={self.host}", "-p", f"port:={self.port}",
                         "-p", f"config_file:={self.config_file}", *more),
                        ready_marker=READY_MARKER)
