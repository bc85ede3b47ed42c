"""Start the node graph as separate processes on a ROS domain of its own, and stop it cleanly.

:data:`GRAPH_NODES` is the one list of what ``exo-ilc run`` starts; the bag recorder runs
in the supervisor's process (:func:`composed`) or as one more :class:`NodeSpec` of its own.
Every child gets the run's ``ROS_DOMAIN_ID`` and, unless the user set it,
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``.
"""

from __future__ import annotations

import ctypes
import fcntl
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO

from ..core.errors import ConfigError, ExoIlcError
from ..nodes import registry

DOMAIN_IDS = range(1, 101)
LOCK_PATTERN = ".exo_ilc_ros_domain_{}.lock"
"""Same lock files as the test session (test/conftest.py), so concurrent runs never share."""


READY_TIMEOUT = 60.0
"""s a node with a ``ready_marker`` may take to print it."""


class GraphError(ExoIlcError):
    """A node of the graph failed, or the graph made no progress."""


@dataclass(frozen=True)
class NodeSpec:
    """One process of the graph: a ROS node run as ``python -m module --ros-args ...``."""

    name: str
    """The node name (and its section in the parameter YAML)."""
    module: str
    arguments: tuple[str, ...] = ()
    """Extra ROS arguments (``-p name:=value`` ...)."""
    executable: str | None = None
    """Run this file instead of ``python -m module`` (e.g. colcon's ``lib/exo_ilc_ros/<node>``)."""
    program_arguments: tuple[str, ...] = ()
    """Arguments before ``--ros-args`` (a container's node names)."""
    ready_marker: str = ""
    """Started before the others, which start once its output holds this text (the live view:
    serving before trial 1, and its start-up off the loop's CPU); "": started with them."""

    def command(self, params_file: Path | str) -> list[str]:
        """The command line of this node with ``params_file``."""
        program = [self.executable] if self.executable else [sys.executable, "-m", self.module]
        return [*program, *self.program_arguments, "--ros-args", "--params-file",
                str(params_file), *self.arguments]


CONTAINER_MODULE = registry.CONTAINER_MODULE


def composed(specs: Sequence[NodeSpec]) -> NodeSpec:
    """One process running the nodes of ``specs`` (``nodes/container.py``), named
    ``a+b``. Their ROS arguments are joined and apply to every node of the process, so node
    parameters must come in params files keyed by node name, not as ``-p``."""
    for spec in specs:
        if "-p" in spec.arguments or "--param" in spec.arguments:
            raise ValueError(f"{spec.name}: -p would apply to every node of the container")
    return NodeSpec("+".join(spec.name for spec in specs), CONTAINER_MODULE,
                    tuple(arg for spec in specs for arg in spec.arguments),
                    program_arguments=tuple(spec.name for spec in specs))


GRAPH_NODES: tuple[NodeSpec, ...] = tuple(NodeSpec(node.name, node.module)
                                          for node in registry.GRAPH)
"""The processes ``exo-ilc run`` starts, in this order (:data:`.nodes.registry.GRAPH`)."""


def graph_nodes(plant: str = "simulator", protocol: str = "services") -> tuple[NodeSpec, ...]:
    """:data:`GRAPH_NODES` with the plant ``plant`` (a key of :data:`registry.PLANTS`: our
    simulator, ``free_running_plant`` for it under ``protocol: homing``, or MuJoCo), run under
    the plant's node name and parameter section."""
    if plant == "simulator" and protocol == "homing":
        plant = "simulator_homing"
    entry = registry.PLANTS[plant]
    return tuple(NodeSpec(spec.name, entry.module) if spec.name == registry.PLANT.name
                 else spec for spec in GRAPH_NODES)


@dataclass
class DomainClaim:
    """A ROS domain id held (through a lock file) until :meth:`release` or process exit."""

    domain_id: int
    handle: IO[str] | None = None

    def release(self) -> None:
        """Give the domain id back."""
        if self.handle is not None:
            self.handle.close()
            self.handle = None


MAX_DOMAIN_ID = 232
"""The largest ROS domain id the DDS port mapping allows (ROS recommends 0-101 on Linux)."""


def exported_domain_id(environment: Mapping[str, str] | None = None) -> int | None:
    """An exported ``ROS_DOMAIN_ID`` (a ROS user's choice, honoured), None when none is;
    :class:`~exo_ilc_ros.core.errors.ConfigError` naming it for a value that is no domain id."""
    text = (os.environ if environment is None else environment).get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return None
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise ConfigError("ROS_DOMAIN_ID", f"the exported value {text!r} is not a domain id "
                          f"(an integer 0-{MAX_DOMAIN_ID}; 0-101 is safe on Linux)")
    return value


def claim_domain_id(requested: int | None = None) -> DomainClaim:
    """A free domain id (lock-file claim), or ``requested`` as given. The search starts at a
    random id: a domain a graph just released is not the next one taken (a process of it that
    outlived its graph, or DDS state not yet gone, would be heard by the next graph)."""
    if requested is not None:
        return DomainClaim(requested)
    first = random.randrange(len(DOMAIN_IDS))
    for domain in [*DOMAIN_IDS[first:], *DOMAIN_IDS[:first]]:
        handle = open(Path(tempfile.gettempdir()) / LOCK_PATTERN.format(domain), "w")  # noqa: SIM115 (held)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            continue
        return DomainClaim(domain, handle)
    raise GraphError(f"no free ROS domain id in {DOMAIN_IDS.start}..{DOMAIN_IDS.stop - 1}")


def graph_environment(domain_id: int, base: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment of the graph's processes: the domain id, discovery on this machine
    unless the user chose a range, and a log directory."""
    env = dict(os.environ if base is None else base)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    if "ROS_AUTOMATIC_DISCOVERY_RANGE" not in env and "ROS_LOCALHOST_ONLY" not in env:
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("ROS_LOG_DIR", str(Path(tempfile.gettempdir()) / "exo_ilc_ros_logs"))
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def _die_with_parent() -> None:  # pragma: no cover - runs in the child before exec
    os.setsid()
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGINT)  # PR_SET_PDEATHSIG: SIGINT when the parent dies
    except OSError:
        pass


@dataclass
class GraphProcesses:
    """The graph's processes: started together, watched, and stopped with SIGINT (then
    SIGKILL for stragglers, and ``fastdds shm clean`` after a kill). A context manager."""

    specs: Sequence[NodeSpec]
    params_file: Path
    env: dict[str, str]
    log_dir: Path
    processes: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    _logs: list[IO[bytes]] = field(default_factory=list)

    def start(self) -> None:
        """Start every node; its stdout and stderr go to ``log_dir/<name>.log``. Nodes with a
        :attr:`NodeSpec.ready_marker` first: the rest once each has printed it."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        first = [spec for spec in self.specs if spec.ready_marker]
        for spec in first:
            self._start(spec)
        for spec in first:
            self._wait_ready(spec)
        for spec in self.specs:
            if not spec.ready_marker:
                self._start(spec)

    def _start(self, spec: NodeSpec) -> None:
        log = open(self.log_dir / f"{spec.name}.log", "wb")  # noqa: SIM115 (closed in stop)
        self._logs.append(log)
        self.processes[spec.name] = subprocess.Popen(
            spec.command(self.params_file), env=self.env, stdin=subprocess.DEVNULL,
            stdout=log, stderr=subprocess.STDOUT, preexec_fn=_die_with_parent)

    def _wait_ready(self, spec: NodeSpec) -> None:
        """Until ``spec``'s log holds its marker (GraphError if it exits or takes more than
        :data:`READY_TIMEOUT` s)."""
        deadline = time.monotonic() + READY_TIMEOUT
        path = self.log_dir / f"{spec.name}.log"
        while spec.ready_marker not in path.read_text(errors="replace"):
            if self.processes[spec.name].poll() is not None:
                self.check()
            if time.monotonic() > deadline:
                raise GraphError(f"node {spec.name} not ready within {READY_TIMEOUT:g} s:\n"
                                 f"{self.log_tail(spec.name)}")
            time.sleep(0.05)

    def log_tail(self, name: str, lines: int = 15) -> str:
        """The last lines a node wrote."""
        path = self.log_dir / f"{name}.log"
        text = path.read_text(errors="replace") if path.exists() else ""
        return "\n".join(text.splitlines()[-lines:])

    def check(self) -> None:
        """GraphError naming a node that exited, with the end of its log."""
        for name, process in self.processes.items():
            code = process.poll()
            if code is not None:
                raise GraphError(f"node {name} exited with code {code}:\n{self.log_tail(name)}")

    def stop(self, timeout: float = 10.0) -> dict[str, int]:
        """SIGINT every node, wait up to ``timeout`` s, SIGKILL the rest; the exit codes."""
        for process in self.processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + timeout
        killed = False
        codes: dict[str, int] = {}
        for name, process in self.processes.items():
            try:
                codes[name] = process.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                codes[name] = process.wait()
                killed = True
        for log in self._logs:
            log.close()
        self._logs.clear()
        if killed:
            clean_shared_memory(self.env)
        return codes

    def __enter__(self) -> GraphProcesses:
        self.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.stop()


def clean_shared_memory(env: Mapping[str, str] | None = None) -> None:
    """``fastdds shm clean``: remove the segments of killed participants (if the tool exists)."""
    tool = Path(sys.prefix) / "bin" / "fastdds"
    if tool.exists():
        subprocess.run([str(tool), "shm", "clean"], env=dict(env or os.environ),
                       stdin=subprocess.DEVNULL, capture_output=True, timeout=30, check=False)
