"""computed_torque_controller: effort = a_N(q) u + c_N(q, qdot), u = u_ff + K_P e + K_D e_dot.

On each /joint_states sample of the current trial it forms eq (11) with the feed-forward and
reference of /ilc/feedforward, then eq (16) with the nominal model, clamps to the effort limits
and publishes on /effort_controller/commands (the ros2_control JointGroupEffortController
convention). Acknowledges every feed-forward it loaded on /diagnostics.

Safety (core.loop.controller, the arithmetic of ``trial.simulate_trial_guarded``): at the first
sample whose |e_j| leaves ``safety.error_envelope`` the trial is aborted at once and the safe hold
(gravity compensation and PD around the pose measured there) is commanded for the rest of it; the
watchdog (``safety.watchdog_periods`` control periods of wall time without /joint_states during
a trial) commands the safe hold around the last pose received. Bad /joint_states or
feed-forward messages are rejected (core.loop.wire_input), logged once per cause and counted; no
effort is ever computed from them. After each trial's last sample the controller reports
``done`` (abort index, watchdog trips) on /diagnostics; its health once a second.
"""

from __future__ import annotations

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from ..core.loop.controller import GuardedControlStep
from ..core.loop.safety import watchdog_for
from ..core.loop.trial import period_ns, sample_index
from ..core.loop.wire_input import Cause, Rejection, validate_feedforward
from ..core.params import schema
from ..core.sim.experiment import Experiment
from ..wire import topics
from ..wire.cdr import float64_array
from ..wire.protocol import trial_of_frame
from ..wire.publishers import max_bytes
from .common import DIAGNOSTICS_QOS, SAMPLES_QOS, CountingPublisher, spin, wall_clock
from .diagnostics import diagnostic_array, stamp_ns, status
from .guard import Health, JointStateGate, Rejections, rejections_check
from .homing_control import HomingControl
from .parameters import SchemaParameters
from .realtime import LoopPriority
from .sender_check import (
    FEEDFORWARD_READER_QOS,
    TRUSTED_READER_QOS,
    TrustedInput,
    decodes,
    deserializing_callback,
    gate_classifier,
)

NAME = schema.CONTROLLER
LATENCY_WINDOW = 100_000


class ComputedTorqueController(Node):
    """Computed torque with the nominal model over feed-forward plus PD feedback."""

    def __init__(self) -> None:
        super().__init__(NAME)
        self.params = SchemaParameters(self, NAME)
        config = self.params.config
        experiment = Experiment(config)
        self.joint_names = config["joint_names"]
        self.step = GuardedControlStep(experiment)
        self.step_ns = period_ns(experiment.period)
        self.rejections = Rejections(self)
        self.gate = JointStateGate(self.joint_names, self.rejections)
        self.watchdog = watchdog_for(config)  # the plant's rule too (core.loop.safety)
        self.aborted_at = -1
        """First sample of the current trial outside the error envelope (-1: none)."""
        self.trial_trips = 0
        self.aborted_trials: list[int] = []
        self.tripped_trials: list[int] = []
        self.holding = False
        self.trial = 0
        self.t0_ns = -1
        self.samples = 0
        self.step_count = experiment.reference.samples
        self.feedforward = np.zeros((0, config.joints))
        self.joint_force: np.ndarray | None = None
        """The identified joint forces of the loaded trial (the points' effort; None: none)."""
        self.effort_limit = list(config["control.effort_limit"])
        self.q_ref = self.feedforward
        self.qd_ref = self.feedforward
        self.pending: bytes | None = None
        self.q = np.zeros(config.joints)
        self.qd = np.zeros(config.joints)
        self.ack_due = False
        self.steps = 0
        self.latency_ns = np.zeros(LATENCY_WINDOW, dtype=np.int64)
        self.latency_count = 0

        self.command_pub = self.create_publisher(Float64MultiArray, topics.EFFORT_COMMANDS,
                                                 SAMPLES_QOS, publisher_class=CountingPublisher)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                                     DIAGNOSTICS_QOS,
                                                     publisher_class=CountingPublisher)
        joints, samples = config.joints, self.step_count
        self.state_sub = TrustedInput(  # the plant's samples only (wire.publishers)
            self, JointState, topics.JOINT_STATES, TRUSTED_READER_QOS, self.on_joint_state,
            self.rejections, max_bytes(topics.JOINT_STATES, joints, samples),
            gate_classifier(JointStateGate(self.joint_names, self.rejections)),
            trusted=config["joint_states_publisher"])
        self.feedforward_sub = TrustedInput(  # the supervisor's profiles only
            self, JointTrajectory, topics.FEEDFORWARD, FEEDFORWARD_READER_QOS,
            deserializing_callback(JointTrajectory, self.on_feedforward, self.rejections,
                                   topics.FEEDFORWARD),
            self.rejections, max_bytes(topics.FEEDFORWARD, joints, samples),
            decodes(JointTrajectory, self.rejections, topics.FEEDFORWARD))
        self.create_timer(0.05, self.on_ack_timer, clock=wall_clock())
        self.create_timer(1.0, self.on_health_timer, clock=wall_clock())
        self.create_timer(max(self.watchdog.timeout_ns / 2e9, 0.002), self.on_watchdog_timer,
                          clock=wall_clock())
        self.health = Health(self, NAME)
        self.health.checks += [self._loop_check, rejections_check(self.rejections, "inputs"),
                               self.state_sub.health, self.feedforward_sub.health]
        self.homing = HomingControl(self, experiment.period, self.step_count) \
            if config["protocol"] == "homing" else None
        """``protocol: homing``: every sample goes to it (nodes/homing_control.py)."""
        ref = experiment.reference
        self.step(ref.acceleration[0], ref.position[0], ref.velocity[0], ref.position[0],
                  ref.velocity[0])  # compile the kernels before the first trial
        self.loop_priority = LoopPriority(self, config["joint_states_publisher"],
                                          config["thread_priority"])
        """SCHED_FIFO once the plant is known to be real time (nodes/realtime.py)."""
        self.priority_timer = self.create_timer(0.2, self.on_priority_timer,
                                                clock=wall_clock())

    def on_priority_timer(self) -> None:
        """Decide the loop's scheduling (the plant's mode), then stop asking."""
        self.loop_priority.poll()
        if self.loop_priority.decided:
            self.priority_timer.cancel()

    def on_feedforward(self, msg: JointTrajectory) -> None:
        """Load the next trial's reference and feed-forward profile (validated first)."""
        frame = msg.header.frame_id
        trial = trial_of_frame(frame)
        if trial is None:
            self.rejections.reject(Rejection(Cause.BAD_STAMP, f"{topics.FEEDFORWARD}: frame_id "
                                             f"{frame!r} is not trial:<k>"))
            return
        if (trial, stamp_ns(msg.header.stamp)) == (self.trial, self.t0_ns) and self.samples:
            self.ack_due = True  # pushed again for want of an acknowledgement: loaded already
            self.on_ack_timer()
            return
        points = msg.points
        samples = self.step_count
        profile = validate_feedforward(
            list(msg.joint_names),
            [int(p.time_from_start.sec) * 1_000_000_000 + int(p.time_from_start.nanosec)
             for p in points],
            [p.positions for p in points], [p.velocities for p in points],
            [p.accelerations for p in points], self.joint_names, samples, self.step_ns,
            joint_force=[p.effort for p in points], effort_limit=self.effort_limit)
        if isinstance(profile, Rejection):
            self.rejections.reject(profile)
            return
        self.feedforward = profile.feedforward
        self.joint_force = profile.joint_force
        self.q_ref = profile.position
        self.qd_ref = profile.velocity
        self.samples = samples
        self.trial = trial
        self.t0_ns = stamp_ns(msg.header.stamp)
        self.aborted_at = -1
        self.step.begin_trial()
        self.trial_trips = 0
        self.holding = False
        self.watchdog.disarm()
        self.gate.restart()
        if self.params.pending is not self.params.config:  # live envelope: trial boundary
            self.step.envelope[:] = self.params.pending["safety.error_envelope"]
        if self.homing is not None:
            self.homing.load(trial, self.t0_ns, profile)
        self.ack_due = True
        self.on_ack_timer()
        if self.pending is not None:
            pending, self.pending = self.pending, None
            self.on_joint_state(pending)

    def on_ack_timer(self) -> None:
        """Acknowledge the loaded feed-forward once linked to the plant both ways."""
        if not self.ack_due or self.command_pub.get_subscription_count() < 1 or \
                self.state_sub.get_publisher_count() < 1 or not self.state_sub.trusted_known():
            return
        self.ack_due = False
        ack = status(topics.FEEDFORWARD_ACK_STATUS, "loaded",
                     [("trial", str(self.trial)), ("t0_ns", str(self.t0_ns))], hardware_id=NAME)
        self.diagnostics_pub.publish(diagnostic_array(self, [ack], self.t0_ns))

    def on_joint_state(self, raw: bytes) -> None:
        """Effort for this sample of the trial (the safe hold once aborted or tripped)."""
        if self.homing is not None:
            self.homing.on_joint_state(raw)
            return
        received = time.perf_counter_ns()
        sample = self.gate(raw)
        if sample is None:
            return
        stamp, q, qd = sample
        i = sample_index(stamp, self.t0_ns, self.step_ns, self.samples)
        if i is None:
            if self.t0_ns < 0 or stamp > self.t0_ns:
                self.pending = raw  # its feed-forward has not arrived yet
                self.gate.restart()
            return
        self.q[:] = q
        self.qd[:] = qd
        if i <= 1:  # armed from the second sample on: the first round trip of a new
            self.watchdog.arm(time.monotonic_ns())  # DDS link may be slow (not a fault)
        else:
            self.watchdog.feed(time.monotonic_ns())
            if self.watchdog.tripped and not self.holding:
                self._trip()
        if self.step.sample(i, self.feedforward[i], self.q_ref[i], self.qd_ref[i], self.q,
                            self.qd, self.holding,
                            None if self.joint_force is None else self.joint_force[i]):
            self.aborted_at = i
            self.aborted_trials.append(self.trial)
            self.get_logger().error(
                f"trial {self.trial}: |e| left the error envelope at sample {i} "
                f"(|e| = {np.abs(self.q_ref[i] - self.q).tolist()}, envelope "
                f"{self.step.envelope.tolist()}); trial aborted, safe hold commanded")
            self._publish_health()
        self.command_pub.publish(float64_array(self.step.effort))
        self.latency_ns[self.latency_count % LATENCY_WINDOW] = time.perf_counter_ns() - received
        self.latency_count += 1
        self.steps += 1
        if i == self.samples - 1:
            self.watchdog.disarm()
            done = status(topics.CONTROLLER_TRIAL_STATUS, "done",
                          [("trial", str(self.trial)), ("t0_ns", str(self.t0_ns)),
                           ("aborted_at", str(self.aborted_at)),
                           ("watchdog_trips", str(self.trial_trips))], hardware_id=NAME)
            self.diagnostics_pub.publish(diagnostic_array(self, [done], stamp))

    def on_watchdog_timer(self) -> None:
        """No /joint_states for the watchdog's timeout during a trial: safe hold, reported."""
        if self.watchdog.check(time.monotonic_ns()):
            self._trip()
            self.command_pub.publish(float64_array(self.step.hold(self.q, self.qd)))

    def _trip(self) -> None:
        self.trial_trips += 1
        self.tripped_trials.append(self.trial)
        if not self.holding and self.aborted_at < 0:
            self.step.hold_at(self.q)
        self.holding = True
        self.get_logger().error(
            f"trial {self.trial}: no /joint_states for {self.watchdog.timeout_ns / 1e6:g} ms "
            f"({self.params.config['safety.watchdog_periods']} control periods); safe hold "
            "commanded around the last pose received")
        self._publish_health()

    def _loop_check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        level = DiagnosticStatus.OK
        reasons = []
        values = [("scheduler", self.loop_priority.scheduler),
                  ("aborted_trials", " ".join(map(str, self.aborted_trials))),
                  ("watchdog_tripped_trials", " ".join(map(str, self.tripped_trials))),
                  *(("watchdog/" + k, v) for k, v in self.watchdog.as_values())]
        if self.holding:
            level = DiagnosticStatus.ERROR
            reasons.append(f"watchdog: no /joint_states in trial {self.trial}; safe hold")
        elif self.aborted_at >= 0:
            level = DiagnosticStatus.ERROR
            reasons.append(f"trial {self.trial} aborted at sample {self.aborted_at} (error "
                           "envelope); safe hold")
        elif self.aborted_trials or self.tripped_trials:
            level = DiagnosticStatus.WARN
            reasons.append(f"{len(self.aborted_trials)} trials aborted (error envelope), "
                           f"{len(self.tripped_trials)} watchdog trips")
        return level, "; ".join(reasons), values

    def on_health_timer(self) -> None:
        """Steps and receive-to-publish latency of the last second on /diagnostics."""
        count = min(self.latency_count, LATENCY_WINDOW)
        values = [("steps", str(self.steps)), ("trial", str(self.trial))]
        if count:
            p50, p99 = np.percentile(self.latency_ns[:count], [50.0, 99.0]) / 1e3
            values += [("latency_samples", str(count)), ("latency_p50_us", repr(float(p50))),
                       ("latency_p99_us", repr(float(p99)))]
        self.latency_count = 0
        self._publish_health(values)

    def _publish_health(self, extra: list[tuple[str, str]] | None = None) -> None:
        health = self.health.status()
        health.values = [*(status("", "", extra or []).values), *health.values]
        self.diagnostics_pub.publish(diagnostic_array(self, [health]))

def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros computed_torque_controller``."""
    return spin(ComputedTorqueController, args)


if __name__ == "__main__":
    raise SystemExit(main())
