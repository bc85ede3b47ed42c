"""computed_torque_controller: effort = a_N(q) u + c_N(q, qdot), u = u_ff + K_P e + K_D e_dot.

On each /joint_states sample of the current trial it forms eq (11) with the feed-forward and
reference of /ilc/feedforward, then eq (16) with the nominal model, clamps to the effort limits
and publishes on /effort_controller/commands (the ros2_control JointGroupEffortController
convention). Acknowledges every feed-forward it loaded on /diagnostics.
"""

from __future__ import annotations

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from .. import topics
from ..core import schema
from ..core.experiment import Experiment
from ..core.loop import ControlStep, period_ns, sample_index
from .cdr import CdrError, float64_array, read_joint_state
from .common import (
    DIAGNOSTICS_QOS,
    LATCHED_QOS,
    SAMPLES_QOS,
    SchemaParameters,
    diagnostic_array,
    spin,
    stamp_ns,
    status,
    wall_clock,
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
        self.step = ControlStep(experiment)
        self.step_ns = period_ns(experiment.period)
        self.trial = 0
        self.t0_ns = -1
        self.samples = 0
        self.feedforward = np.zeros((0, config.joints))
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
                                                 SAMPLES_QOS)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                                     DIAGNOSTICS_QOS)
        self.state_sub = self.create_subscription(JointState, topics.JOINT_STATES,
                                                  self.on_joint_state, SAMPLES_QOS, raw=True)
        self.create_subscription(JointTrajectory, topics.FEEDFORWARD, self.on_feedforward,
                                 LATCHED_QOS)
        self.create_timer(0.05, self.on_ack_timer, clock=wall_clock())
        self.create_timer(1.0, self.on_health_timer, clock=wall_clock())
        ref = experiment.reference
        self.step(ref.acceleration[0], ref.position[0], ref.velocity[0], ref.position[0],
                  ref.velocity[0])  # compile the kernels before the first trial

    def on_feedforward(self, msg: JointTrajectory) -> None:
        """Load the next trial's reference and feed-forward profile."""
        if list(msg.joint_names) != self.joint_names:
            self.get_logger().error(f"feed-forward for joints {list(msg.joint_names)} ignored; "
                                    f"this controller drives {self.joint_names}")
            return
        frame = msg.header.frame_id
        if not frame.startswith(topics.FEEDFORWARD_FRAME_PREFIX):
            self.get_logger().error(f"feed-forward with frame_id {frame!r} ignored")
            return
        points = msg.points
        self.feedforward = np.array([p.accelerations for p in points], dtype=float)
        self.q_ref = np.array([p.positions for p in points], dtype=float)
        self.qd_ref = np.array([p.velocities for p in points], dtype=float)
        self.samples = len(points)
        self.trial = int(frame[len(topics.FEEDFORWARD_FRAME_PREFIX):])
        self.t0_ns = stamp_ns(msg.header.stamp)
        self.ack_due = True
        self.on_ack_timer()
        if self.pending is not None:
            pending, self.pending = self.pending, None
            self.on_joint_state(pending)

    def on_ack_timer(self) -> None:
        """Acknowledge the loaded feed-forward once linked to the plant both ways."""
        if not self.ack_due or self.command_pub.get_subscription_count() < 1 or \
                self.state_sub.get_publisher_count() < 1:
            return
        self.ack_due = False
        ack = status(topics.FEEDFORWARD_ACK_STATUS, "loaded",
                     [("trial", str(self.trial)), ("t0_ns", str(self.t0_ns))], hardware_id=NAME)
        self.diagnostics_pub.publish(diagnostic_array(self, [ack], self.t0_ns))

    def on_joint_state(self, raw: bytes) -> None:
        """Effort for this sample of the trial."""
        received = time.perf_counter_ns()
        try:
            stamp, q, qd = read_joint_state(raw)
        except CdrError as exc:
            self.get_logger().error(f"bad joint state ignored: {exc}", throttle_duration_sec=5.0)
            return
        i = sample_index(stamp, self.t0_ns, self.step_ns, self.samples)
        if i is None:
            if self.t0_ns < 0 or stamp > self.t0_ns:
                self.pending = raw  # its feed-forward has not arrived yet
            return
        if q.shape[0] != self.q.shape[0] or qd.shape[0] != q.shape[0]:
            self.get_logger().error("joint state of the wrong size ignored",
                                    throttle_duration_sec=5.0)
            return
        self.q[:] = q
        self.qd[:] = qd
        effort = self.step(self.feedforward[i], self.q_ref[i], self.qd_ref[i], self.q, self.qd)
        self.command_pub.publish(float64_array(effort))
        self.latency_ns[self.latency_count % LATENCY_WINDOW] = time.perf_counter_ns() - received
        self.latency_count += 1
        self.steps += 1

    def on_health_timer(self) -> None:
        """Steps and receive-to-publish latency of the last second on /diagnostics."""
        count = min(self.latency_count, LATENCY_WINDOW)
        values = [("steps", str(self.steps)), ("trial", str(self.trial))]
        if count:
            p50, p99 = np.percentile(self.latency_ns[:count], [50.0, 99.0]) / 1e3
            values += [("latency_samples", str(count)), ("latency_p50_us", repr(float(p50))),
                       ("latency_p99_us", repr(float(p99)))]
        self.latency_count = 0
        health = status(topics.CONTROLLER_HEALTH_STATUS, "ok", values, hardware_id=NAME)
        self.diagnostics_pub.publish(diagnostic_array(self, [health]))


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros computed_torque_controller``."""
    return spin(ComputedTorqueController, args)


if __name__ == "__main__":
    raise SystemExit(main())
