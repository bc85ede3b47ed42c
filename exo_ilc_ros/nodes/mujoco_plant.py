"""mujoco_plant: the arm simulated by MuJoCo (``core/sim/mujoco_arm.py``), as the graph's plant,
without reset or start services: it behaves as an arm does, so the trials need ``protocol:
homing``.

It runs under the plant's node name (``plant_simulator``: the same parameter section, so the
supervisor reads its mass uncertainty as from our simulator) and publishes ``/joint_states`` and
``/clock``, takes ``/effort_controller/commands``. ``mode: lock_step`` advances one control
period per command and nothing else (the first sample goes out once a controller is linked, and
again after 1 s while no command came); ``real_time`` steps on a wall-clock timer with the last
command held, and after ``safety.watchdog_periods`` periods of wall time without a command
applies the safe hold around the pose of that moment instead, until commands come again.

:class:`FreeRunningPlant` is the node with any stepper; ``free_running_plant`` runs it with our
own simulator's RK4 (``core/loop/plant.py``): our simulator as any arm, for ``protocol: homing``.
Commands are checked and clamped as in ``plant_simulator``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ..core.loop.controller import GuardedControlStep
from ..core.loop.stepper import PlantStepper
from ..core.loop.trial import period_ns
from ..core.params import schema
from ..core.params.validation import Cause, Rejection, validate_effort_command
from ..core.sim.experiment import Experiment
from ..core.sim.mujoco_arm import MujocoArm, effects_not_simulated
from ..wire import topics
from ..wire.cdr import CdrError, JointStateWriter, read_float64_array
from ..wire.publishers import max_bytes
from .common import CLOCK_QOS, DIAGNOSTICS_QOS, SAMPLES_QOS, CountingPublisher, spin, wall_clock
from .diagnostics import diagnostic_array
from .guard import Health, Rejections, effort_limit_reasons, rejections_check
from .identified import TRUSTED_READER_QOS, TrustedInput, effort_classifier
from .parameters import SchemaParameters
from .realtime import plant_scheduling

NAME = schema.PLANT
FIRST_SAMPLE_AGAIN = 1.0
"""Lock-step: wall seconds without any command before the first sample is sent again (it may
have gone out before the controller's subscription matched)."""


class FreeRunningPlant(Node):
    """A plant that keeps its own clock and offers no services (``stepper``: position,
    velocity, applied, step(effort, saturated))."""

    engine = "rk4"

    def __init__(self) -> None:
        super().__init__(NAME)
        self.params = SchemaParameters(self, NAME)
        config = self.params.config
        self.experiment = Experiment(config)
        self.stepper: Any = self.make_stepper()
        ref = self.experiment.reference
        self.stepper_state(ref.position[0], ref.velocity[0])
        self.lock_step = config["mode"] == "lock_step"
        self.clock_every = int(config["clock_every"])
        self.step_ns = period_ns(self.experiment.period)
        self.now_ns = self.step_ns
        self.index = 0
        self.started = False
        self.limit = np.asarray(self.experiment.effort_limit, dtype=float)
        self.held = np.zeros(config.joints)
        self.rejections = Rejections(self)
        self.saturated = np.zeros(config.joints, dtype=np.int64)
        self.over_limit = 0
        self.commands = 0
        self.stalls = 0
        """Periods the plant stepped on its own (the safe hold): no command came in time."""
        self.timeout_ns = int(config["safety.watchdog_periods"]) * self.step_ns
        """Real time: wall time without a command before the safe hold."""
        self.last_command_ns = 0
        self.hold_pose: np.ndarray | None = None
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
            self, Float64MultiArray, topics.EFFORT_COMMANDS, TRUSTED_READER_QOS, self.on_command,
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
        wall_period = self.experiment.period / config["real_time_rate"]
        self.create_timer(wall_period if not self.lock_step else 0.05, self.on_tick,
                          clock=wall_clock())
        self.scheduler = plant_scheduling(self, config["thread_priority"], self.lock_step)
        self.get_logger().info(
            f"{self.engine} plant without services ({config['mode']}), mass uncertainty "
            f"{self.experiment.mass_uncertainty:g}; trials need protocol: homing")

    def make_stepper(self) -> Any:
        """Our simulator's RK4 stepper."""
        return PlantStepper(self.experiment)

    def stepper_state(self, q: np.ndarray, qd: np.ndarray) -> None:
        """Where the arm is when the node starts (at rest at q_d(0))."""
        self.stepper.position[:] = q
        self.stepper.velocity[:] = qd

    def on_command(self, raw: bytes) -> None:
        """Lock-step: apply the command over one period and publish the next sample;
        real-time: hold it. A command that is not one finite value per joint is rejected."""
        try:
            effort = read_float64_array(raw)
        except CdrError as exc:
            self.rejections.reject(Rejection(Cause.NOT_NUMERIC, f"{topics.EFFORT_COMMANDS}: "
                                             f"undecodable: {exc}"))
            return
        if effort.shape != self.held.shape or not np.isfinite(effort).all():
            checked = validate_effort_command(effort.tolist(), [np.inf] * self.held.shape[0])
            self.rejections.reject(checked if isinstance(checked, Rejection) else Rejection(
                Cause.NOT_NUMERIC, f"{topics.EFFORT_COMMANDS}: not one finite value per joint"))
            return
        self.commands += 1
        if np.any(np.abs(effort) > self.limit):
            self.over_limit += 1
        self.held[:] = effort
        self.last_command_ns = time.monotonic_ns()
        if self.hold_pose is not None:
            self.hold_pose = None
            self.get_logger().info("effort commands again; safe hold released")
        if self.lock_step and self.started:
            self._advance(self.held)

    def on_tick(self) -> None:
        """Both modes: start once a controller is linked. Lock-step: nothing moves without a
        command (simulated time stands still, as in plant_simulator); the first sample is sent
        again while no command ever came. Real time: one period with the held command, the
        safe hold once no command came for the timeout."""
        now = time.monotonic_ns()
        if not self.started:
            if self.state_pub.get_subscription_count() >= 1 and \
                    self.command_sub.get_publisher_count() >= 1 and \
                    self.command_sub.trusted_known():
                self.started = True
                self.last_command_ns = now
                self._publish()
            return
        if self.lock_step:
            if not self.commands and now - self.last_command_ns > FIRST_SAMPLE_AGAIN * 1e9:
                self.last_command_ns = now
                self._publish()
            return
        if self.hold_pose is None and \
                time.monotonic_ns() - self.last_command_ns > self.timeout_ns:
            self.hold_pose = np.array(self.stepper.position)
            self.safe_hold.hold_at(self.hold_pose)
            self.get_logger().error(
                f"no effort command for {self.timeout_ns / 1e6:g} ms: safe hold around the "
                "current pose until commands come again")
            self.on_health_timer()
        if self.hold_pose is not None:
            effort = self.safe_hold.hold(np.array(self.stepper.position),
                                         np.array(self.stepper.velocity))
            self.stalls += 1
            self._advance(effort)
        else:
            self._advance(self.held)

    def _advance(self, effort: np.ndarray) -> None:
        self.stepper.step(effort, self.saturated)
        self.index += 1
        self.now_ns += self.step_ns
        self._publish()

    def _publish(self) -> None:
        stepper = self.stepper
        self.state_pub.publish(self.state.write(self.now_ns, stepper.position, stepper.velocity,
                                                stepper.applied))
        if self.index % self.clock_every:
            return
        self.clock.clock.sec, self.clock.clock.nanosec = divmod(self.now_ns, 1_000_000_000)
        self.clock_pub.publish(self.clock)

    def on_health_timer(self) -> None:
        """Health on /diagnostics: rejections, saturation, the safe hold."""
        self.diagnostics_pub.publish(diagnostic_array(self, [self.health.status()]))

    def _effort_check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        names = self.params.config["joint_names"]
        values = [("engine", self.engine), ("scheduler", self.scheduler),
                  ("commands", str(self.commands)),
                  ("over_limit", str(self.over_limit)), ("stalls", str(self.stalls)),
                  ("simulated_time_ns", str(self.now_ns)),
                  *((f"saturated/{n}", str(int(c))) for n, c in zip(names, self.saturated,
                                                                      strict=True))]
        reasons = []
        level = DiagnosticStatus.OK
        if self.hold_pose is not None:
            level = DiagnosticStatus.ERROR
            reasons.append("no effort command; safe hold")
        limit_level, limit_reasons = effort_limit_reasons(names, self.saturated,
                                                          self.over_limit)
        return max(level, limit_level), "; ".join(reasons + limit_reasons), values


class MujocoPlant(FreeRunningPlant):
    """The arm in MuJoCo (core/sim/mujoco_arm.py): masses scaled by (1 + mass_uncertainty), RK4 at
    ``integration_step``."""

    engine = "mujoco"

    def make_stepper(self) -> Any:
        """MuJoCo's arm of this configuration."""

        config = self.params.config
        if config["dynamics"] != "full":
            self.get_logger().warning("dynamics: MuJoCo always simulates the full plant "
                                      f"(eq (15)); {config['dynamics']!r} ignored")
        missing = effects_not_simulated(config)
        if missing:
            self.get_logger().warning("virtual patient: MuJoCo simulates friction, passive and "
                                      "spastic stiffness and damping only; not simulated here: "
                                      + ", ".join(missing))
        return MujocoArm.from_config(config, self.experiment.mass_uncertainty)

    def stepper_state(self, q: np.ndarray, qd: np.ndarray) -> None:
        """At rest at q_d(0) when the node starts."""
        self.stepper.set_state(q, qd)


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros mujoco_plant``."""
    return spin(MujocoPlant, args)


if __name__ == "__main__":
    raise SystemExit(main())
