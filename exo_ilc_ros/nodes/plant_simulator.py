"""plant_simulator: the arm with its true masses, integrated one control period at a time.

Publishes /joint_states and /clock, takes efforts on /effort_controller/commands, and offers
the reset/start services of the trial protocol (see :mod:`exo_ilc_ros.wire.topics`). With a
virtual patient (``patient.*``, :mod:`exo_ilc_ros.core.loop.patient`) /joint_states carries what
the sensors measure and /ground_truth/joint_states the true state; the trial number (for the
patient's per-trial draws) comes from the frame of the trial's /ilc/feedforward. Lock-step mode
advances one period per command; real-time mode steps on a wall-clock timer with the last
command held.

Safety: every command is checked (one finite value per joint, else rejected: logged once per
cause, counted, never applied) and clamped again to ``control.effort_limit``; samples at the
limit are counted per joint (saturation, on /diagnostics). In real-time mode a watchdog
(``safety.watchdog_periods`` periods of wall time without a command during a trial) stops holding
the last command and applies the safe hold (nominal gravity compensation and PD around the pose
at the trip) instead, until the next trial.
"""

from __future__ import annotations

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rclpy.timer import Timer
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from ..core.loop.controller import GuardedControlStep
from ..core.loop.plant import clamp_counted
from ..core.loop.safety import LateCommands, watchdog_for
from ..core.loop.stepper import PlantStepper
from ..core.loop.trial import period_ns
from ..core.params import schema
from ..core.params.validation import Cause, Rejection, validate_effort_command
from ..core.sim.experiment import Experiment
from ..wire import topics
from ..wire.cdr import CdrError, JointStateWriter, read_float64_array
from ..wire.protocol import trial_of_frame
from ..wire.publishers import max_bytes
from .common import CLOCK_QOS, DIAGNOSTICS_QOS, SAMPLES_QOS, CountingPublisher, spin, wall_clock
from .diagnostics import diagnostic_array, stamp_ns, status
from .guard import Health, Rejections, effort_limit_reasons, rejections_check
from .identified import (
    FEEDFORWARD_READER_QOS,
    TRUSTED_READER_QOS,
    TrustedInput,
    decoded,
    decodes,
    effort_classifier,
)
from .parameters import SchemaParameters
from .realtime import plant_scheduling

NAME = schema.PLANT


class PlantSimulator(Node):
    """The simulated exoskeleton arm (true masses, ``mass_uncertainty``)."""

    def __init__(self) -> None:
        super().__init__(NAME)
        self.params = SchemaParameters(self, NAME)
        config = self.params.config
        self.experiment = Experiment(config)
        self.stepper = PlantStepper(self.experiment)
        self.lock_step = config["mode"] == "lock_step"
        self.clock_every = int(config["clock_every"])
        self.step_ns = period_ns(self.experiment.period)
        self.last_index = self.experiment.reference.samples - 1
        self.now_ns = 0
        self.t0_ns = 0
        self.index = 0
        self.armed = False
        self.running = False
        self.held = np.zeros(config.joints)
        self.unapplied = np.zeros(config.joints)
        """Lock-step: where a command received between trials is clamped (never applied)."""
        self.timer: Timer | None = None
        self.limit = np.asarray(self.experiment.effort_limit, dtype=float)
        self.unbounded = np.full(config.joints, np.inf)
        self.rejections = Rejections(self)
        self.saturated = np.zeros(config.joints, dtype=np.int64)
        self.over_limit = 0
        self.commands = 0
        self.watchdog = watchdog_for(config)  # the controller's rule too (core.loop.safety)
        self.late = LateCommands()  # real time: periods run on a late (held) command
        self.hold_pose: np.ndarray | None = None
        """Real-time mode: the pose the plant's safe hold keeps after a watchdog trip."""
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
        self.patient = self.experiment.patient
        self.next_trial: tuple[int, int] | None = None
        """(trial k, t0) of the last /ilc/feedforward: the patient's draws are trial k's."""
        self.truth = JointStateWriter(config["joint_names"])
        self.truth_pub = self.create_publisher(
            JointState, topics.TRUE_JOINT_STATES, SAMPLES_QOS,
            publisher_class=CountingPublisher) if self.patient.measures else None
        self.feedforward_sub = TrustedInput(  # the supervisor's profiles only: their trial
            self, JointTrajectory, topics.FEEDFORWARD, FEEDFORWARD_READER_QOS,
            decoded(JointTrajectory, self.on_feedforward, self.rejections, topics.FEEDFORWARD),
            self.rejections, max_bytes(topics.FEEDFORWARD, config.joints,
                                       self.experiment.reference.position.shape[0]),
            decodes(JointTrajectory, self.rejections, topics.FEEDFORWARD)) \
            if self.patient.enabled else None
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                                     DIAGNOSTICS_QOS,
                                                     publisher_class=CountingPublisher)
        self.health = Health(self, NAME)
        self.health.checks += [self._effort_check, rejections_check(self.rejections,
                                                                    "effort commands"),
                               self.command_sub.health]
        self.create_timer(1.0, self.on_health_timer, clock=wall_clock())
        self.create_service(Trigger, topics.RESET_SERVICE, self.on_reset)
        self.create_service(Trigger, topics.START_SERVICE, self.on_start)
        if not self.lock_step:
            wall_period = self.experiment.period / config["real_time_rate"]
            self.timer = self.create_timer(wall_period, self.on_tick, clock=wall_clock(),
                                           autostart=False)
        self.stepper.step(self.held)  # compile the kernels now, not in the first trial
        if self.patient.enabled:
            self.stepper.begin_trial(1)
            self.stepper.measure()
            self.stepper.step(self.held)
        self.stepper.reset()
        self.scheduler = plant_scheduling(self, config["thread_priority"], self.lock_step)
        self.get_logger().info(
            f"{config['mode']} plant, mass uncertainty {self.experiment.mass_uncertainty:g}, "
            f"{self.last_index + 1} samples per trial")

    def on_reset(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        """Put the arm at x_d(0), stop stepping, announce the next trial's t0."""
        self._stop()
        self.stepper.reset()
        self.held[:] = 0.0
        self.hold_pose = None
        self.t0_ns = self.now_ns + self.step_ns
        self.armed = True
        response.success = True
        response.message = f"{topics.T0_PREFIX}{self.t0_ns}"
        return response

    def on_feedforward(self, msg: JointTrajectory) -> None:
        """The trial number of the next trial (frame ``trial:<k>``, stamp t0): the virtual
        patient draws trial k's random numbers (only the header is read)."""
        trial = trial_of_frame(msg.header.frame_id)
        if trial is not None:
            self.next_trial = (trial, stamp_ns(msg.header.stamp))

    def on_start(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        """Publish sample 0 and step until the last sample."""
        if not self.armed:
            response.success = False
            response.message = "call reset before start"
            return response
        if self.state_pub.get_subscription_count() < 1 or \
                self.command_sub.get_publisher_count() < 1 or \
                not self.command_sub.trusted_known():
            response.success = False
            response.message = "waiting for a controller on " + topics.EFFORT_COMMANDS
            return response
        if self.patient.enabled:
            if self.next_trial is None or self.next_trial[1] != self.t0_ns:
                response.success = False
                response.message = (f"waiting for the trial's {topics.FEEDFORWARD} (t0 "
                                    f"{self.t0_ns} ns): the virtual patient draws per trial")
                return response
            try:
                self.stepper.begin_trial(self.next_trial[0])
            except ValueError as exc:
                response.success = False
                response.message = str(exc)
                return response
        self.armed = False
        self.running = True
        self.index = 0
        self.now_ns = self.t0_ns
        self._publish()
        if self.timer is not None:
            self.watchdog.arm(time.monotonic_ns())
            self.late.start()
            self.timer.reset()
        response.success = True
        response.message = f"{topics.T0_PREFIX}{self.t0_ns}"
        return response

    def on_command(self, raw: bytes) -> None:
        """Lock-step: apply the command for the current sample and advance; real-time: hold.
        A command that is not one finite value per joint is rejected (never applied)."""
        try:
            effort = read_float64_array(raw)
        except CdrError as exc:
            self.rejections.reject(Rejection(Cause.NOT_NUMERIC, f"{topics.EFFORT_COMMANDS}: "
                                             f"undecodable: {exc}"))
            return
        if effort.shape != self.held.shape:
            self._reject(effort)
            return
        if self.lock_step and self.running:  # the hot path: check, count, clamp, step at once
            beyond = self.stepper.step(effort, self.saturated)
        else:  # real time: the command to hold; lock-step between trials: only checked
            beyond = clamp_counted(effort, self.limit, self.saturated,
                                   self.unapplied if self.lock_step else self.held)
        if beyond < 0:
            self._reject(effort)
            return
        self.commands += 1
        if beyond:
            self.over_limit += 1
        if self.lock_step:
            if self.running:
                self._stepped()
        elif self.running:
            self.watchdog.feed(time.monotonic_ns())
            self.late.command()

    def _reject(self, effort: np.ndarray) -> None:
        checked = validate_effort_command(effort.tolist(), self.unbounded.tolist())
        self.rejections.reject(checked if isinstance(checked, Rejection) else Rejection(
            Cause.NOT_NUMERIC, f"{topics.EFFORT_COMMANDS}: not one finite value per joint"))

    def on_tick(self) -> None:
        """Real-time mode: one period with the held command (the safe hold after a trip)."""
        if not self.running:
            return
        if self.watchdog.check(time.monotonic_ns()) or \
                (self.watchdog.tripped and self.hold_pose is None):
            self.hold_pose = self.stepper.position.copy()
            self.safe_hold.hold_at(self.hold_pose)
            self.get_logger().error(
                f"no effort command for {self.watchdog.timeout_ns / 1e6:g} ms: stopped holding "
                "the last command; safe hold around the current pose until the next trial")
            self.on_health_timer()
        if self.hold_pose is not None:
            self.held[:] = self.safe_hold.hold(self.stepper.position, self.stepper.velocity)
        self.late.tick()
        self._advance(self.held)
        if not self.running:  # that was the last sample: the trial's lateness, for the supervisor
            self.diagnostics_pub.publish(diagnostic_array(self, [status(
                topics.PLANT_TRIAL_STATUS, "done", [("t0_ns", str(self.t0_ns)),
                                                     ("periods", str(self.late.periods)),
                                                     ("late_commands", str(self.late.trial)),
                                                     ("first_late", str(self.late.first))],
                hardware_id=NAME)]))

    def on_health_timer(self) -> None:
        """Health on /diagnostics: rejections, saturation, watchdog."""
        self.diagnostics_pub.publish(diagnostic_array(self, [self.health.status()]))

    def _effort_check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        names = self.params.config["joint_names"]
        values = [("commands", str(self.commands)), ("over_limit", str(self.over_limit)),
                  *((f"saturated/{n}", str(int(c))) for n, c in zip(names, self.saturated,
                                                                      strict=True)),
                  *(("watchdog/" + k, v) for k, v in self.watchdog.as_values()),
                  *self.late.as_values(), ("scheduler", self.scheduler)]
        reasons = []
        level = DiagnosticStatus.OK
        if self.hold_pose is not None:
            level = DiagnosticStatus.ERROR
            reasons.append("watchdog: no effort command; safe hold")
        limit_level, limit_reasons = effort_limit_reasons(names, self.saturated,
                                                          self.over_limit)
        return max(level, limit_level), "; ".join(reasons + limit_reasons), values

    def _advance(self, effort: np.ndarray) -> None:
        self.stepper.step(effort)
        self._stepped()

    def _stepped(self) -> None:
        self.index += 1
        self.now_ns += self.step_ns
        self._publish()
        if self.index >= self.last_index:
            self._stop()

    def _stop(self) -> None:
        self.running = False
        self.watchdog.disarm()
        if self.timer is not None:
            self.timer.cancel()

    def _publish(self) -> None:
        stepper = self.stepper
        position, velocity = stepper.measure()
        self.state_pub.publish(self.state.write(self.now_ns, position, velocity,
                                                stepper.applied))
        if self.truth_pub is not None:
            self.truth_pub.publish(self.truth.write(self.now_ns, stepper.position,
                                                    stepper.velocity, stepper.applied))
        if self.index % self.clock_every and self.index < self.last_index:
            return  # /clock at every clock_every-th sample, the first and the last
        sec, nanosec = divmod(self.now_ns, 1_000_000_000)
        self.clock.clock.sec = sec
        self.clock.clock.nanosec = nanosec
        self.clock_pub.publish(self.clock)


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros plant_simulator``."""
    return spin(PlantSimulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
