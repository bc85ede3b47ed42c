"""What every plant node shares (:class:`PlantNode`): the node's parameters and experiment, the
samples and ``/clock`` it publishes, the controller's effort commands it trusts (checked: a
command that is not one finite value per joint is refused, counted, never applied), saturation
counts, the watchdog of :func:`exo_ilc_ros.core.loop.safety.watchdog_for` with the controller's
safe hold it commands after a trip, a state that stopped being finite
(:meth:`PlantNode.report_divergence`: no sample of it is sent; ``diverged`` on ``/diagnostics``
for the supervisor, with the time, the joint and the cause) and its health on
``/diagnostics``. ``plant_simulator`` (our
simulator, with the trial protocol's services) and the free-running plants (``mujoco_plant``,
``free_running_plant``) add how and when they step."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ..core.loop.controller import GuardedControlStep
from ..core.loop.divergence import PlantDivergence
from ..core.loop.safety import watchdog_for
from ..core.loop.trial import period_ns
from ..core.loop.wire_input import Cause, Rejection, validate_effort_command
from ..core.params import schema
from ..core.person.experiment import experiment_for
from ..wire import topics
from ..wire.cdr import CdrError, JointStateWriter, read_float64_array
from ..wire.publishers import max_bytes
from .common import CLOCK_QOS, DIAGNOSTICS_QOS, SAMPLES_QOS, CountingPublisher, wall_clock
from .diagnostics import diagnostic_array, status
from .guard import Health, Rejections, effort_limit_reasons, rejections_check
from .parameters import SchemaParameters
from .sender_check import TRUSTED_READER_QOS, TrustedInput, effort_classifier

NAME = schema.PLANT
"""Every plant runs under this node name (one parameter section, whichever plant it is)."""


class Pace:
    """A lock-step plant at a pace a person can follow (``pace``, ``exo-ilc run --live-pace``):
    each sample is published no earlier than its simulated time over ``rate`` after the sample
    it counts from, in wall time. It only waits: no number changes (0: unpaced)."""

    def __init__(self, rate: float) -> None:
        self.rate = rate
        self.wall_ns = 0
        self.sim_ns = 0

    def start(self, sim_ns: int) -> None:
        """Count from now, at simulated time ``sim_ns`` (a trial's first sample)."""
        self.wall_ns, self.sim_ns = time.monotonic_ns(), sim_ns

    def wait(self, sim_ns: int) -> None:
        """Sleep until the sample at ``sim_ns`` is due."""
        if self.rate <= 0.0:
            return
        due = self.wall_ns + (sim_ns - self.sim_ns) / self.rate
        wait = (due - time.monotonic_ns()) / 1e9
        if wait > 0.0:
            time.sleep(wait)


class PlantNode(Node):
    """The parts every plant node shares (module docstring); ``on_command`` receives the
    controller's commands as CDR bytes (:meth:`command_of` decodes and checks them)."""

    def __init__(self, on_command: Callable[[bytes], None]) -> None:
        super().__init__(NAME)
        self.params = SchemaParameters(self, NAME)
        config = self.params.config
        self.experiment = experiment_for(config)
        """The closed loop of the config (a person with muscles: its strapped model)."""
        self.lock_step = config["mode"] == "lock_step"
        self.clock_every = int(config["clock_every"])
        self.step_ns = period_ns(self.experiment.period)
        self.limit = np.asarray(self.experiment.effort_limit, dtype=float)
        self.held = np.zeros(config.joints)
        """The command the plant holds over a period (real time), or the safe hold's."""
        self.rejections = Rejections(self)
        self.saturated = np.zeros(config.joints, dtype=np.int64)
        self.over_limit = 0
        self.commands = 0
        self.watchdog = watchdog_for(config)  # the controller's rule too (core.loop.safety)
        self.hold_pose: np.ndarray | None = None
        """Real time: the pose the plant's safe hold keeps after a watchdog trip."""
        self.diverged: PlantDivergence | None = None
        """The plant's state stopped being finite (until the next trial's reset; a plant
        without reset stays so): no sample is sent."""
        self.safe_hold = GuardedControlStep(self.experiment)
        """The controller's safe hold (its gains and ramp, core/loop/hold.py), latched at the
        trip."""
        here = np.zeros(config.joints)  # load its kernels now, not at a trip
        self.safe_hold.hold_at(here)
        self.safe_hold.hold(here, here)
        self.state = JointStateWriter(config["joint_names"])
        self.clock = Clock()
        self.state_pub = self.create_publisher(JointState, topics.JOINT_STATES, SAMPLES_QOS,
                                               publisher_class=CountingPublisher)
        self.clock_pub = self.create_publisher(Clock, topics.CLOCK, CLOCK_QOS,
                                               publisher_class=CountingPublisher)
        self.command_sub = TrustedInput(  # the controller's commands only (wire.publishers)
            self, Float64MultiArray, topics.EFFORT_COMMANDS, TRUSTED_READER_QOS, on_command,
            self.rejections, max_bytes(topics.EFFORT_COMMANDS, config.joints, 0),
            effort_classifier(self.rejections, config.joints))
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                                     DIAGNOSTICS_QOS,
                                                     publisher_class=CountingPublisher)
        self.health = Health(self, NAME)
        self.health.checks += [self._effort_check, rejections_check(self.rejections,
                                                                    "effort commands"),
                               self.command_sub.health]
        self.create_timer(1.0, self.on_health_timer, clock=wall_clock())

    def command_of(self, raw: bytes) -> np.ndarray | None:
        """The effort command in ``raw``, or None (refused and counted) if it does not decode."""
        try:
            return read_float64_array(raw)
        except CdrError as exc:
            self.rejections.reject(Rejection(Cause.NOT_NUMERIC, f"{topics.EFFORT_COMMANDS}: "
                                             f"undecodable: {exc}"))
            return None

    def reject_effort(self, effort: np.ndarray) -> None:
        """Refuse and count a command that is not one finite value per joint, naming why."""
        checked = validate_effort_command(effort.tolist(), [np.inf] * self.held.shape[0])
        self.rejections.reject(checked if isinstance(checked, Rejection) else Rejection(
            Cause.NOT_NUMERIC, f"{topics.EFFORT_COMMANDS}: not one finite value per joint"))

    def latch_safe_hold(self, position: np.ndarray, why: str) -> None:
        """The watchdog tripped: the safe hold around ``position`` from now on, said once."""
        self.hold_pose = np.array(position)
        self.safe_hold.hold_at(self.hold_pose)
        self.get_logger().error(f"no effort command for {self.watchdog.timeout_ns / 1e6:g} ms: "
                                f"{why}")
        self.on_health_timer()

    def report_divergence(self, divergence: PlantDivergence, stamp_ns: int,
                          t0_ns: int = -1) -> None:
        """The state is not finite at the sample stamped ``stamp_ns`` (of the trial that
        started at ``t0_ns``, -1: not known here): said once in the log, and as
        ``plant_simulator/trial`` ``diverged`` on /diagnostics (``stamp_ns``, ``t0_ns``,
        ``joint``, ``joint_name``, ``time`` (s of simulated time), ``cause``) for the
        supervisor, which ends the trial there; the health is ERROR until a reset."""
        self.diverged = divergence
        self.get_logger().error(
            f"the plant diverged at simulated time {stamp_ns / 1e9:.3f} s on joint "
            f"{divergence.joint_name}: {divergence.cause}; no sample of it is sent, the trial "
            "is stopped there")
        self.diagnostics_pub.publish(diagnostic_array(self, [status(
            topics.PLANT_TRIAL_STATUS, "diverged",
            [("stamp_ns", str(stamp_ns)), ("t0_ns", str(t0_ns)),
             ("joint", str(divergence.joint)), ("joint_name", divergence.joint_name),
             ("time", repr(stamp_ns / 1e9)), ("cause", divergence.cause)],
            hardware_id=NAME)]))
        self.on_health_timer()

    def publish_clock(self, now_ns: int) -> None:
        """``/clock`` at ``now_ns`` of simulated time."""
        self.clock.clock.sec, self.clock.clock.nanosec = divmod(now_ns, 1_000_000_000)
        self.clock_pub.publish(self.clock)

    def on_health_timer(self) -> None:
        """Health on /diagnostics: rejections, saturation, the watchdog and the safe hold."""
        self.diagnostics_pub.publish(diagnostic_array(self, [self.health.status()]))

    def effort_values(self) -> list[tuple[str, str]]:
        """The plant's own key-values of its health (besides the counts every plant gives)."""
        return []

    hold_reason = "watchdog: no effort command; safe hold"
    """Why the health is ERROR while the safe hold is on."""

    def _effort_check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        names = self.params.config["joint_names"]
        values = [("commands", str(self.commands)), ("over_limit", str(self.over_limit)),
                  *((f"saturated/{n}", str(int(c))) for n, c in zip(names, self.saturated,
                                                                      strict=True)),
                  *(("watchdog/" + k, v) for k, v in self.watchdog.as_values()),
                  *self.effort_values()]
        reasons = []
        level = DiagnosticStatus.OK
        if self.hold_pose is not None:
            level = DiagnosticStatus.ERROR
            reasons.append(self.hold_reason)
        if self.diverged is not None:
            level = DiagnosticStatus.ERROR
            reasons.append(f"the plant diverged on joint {self.diverged.joint_name}: "
                           f"{self.diverged.cause}")
        limit_level, limit_reasons = effort_limit_reasons(names, self.saturated,
                                                          self.over_limit)
        return max(level, limit_level), "; ".join(reasons + limit_reasons), values
