"""ilc_supervisor: runs the trials and learns between them.

Per trial: reset the plant (learning its t0), push the feed-forward (latched /ilc/feedforward),
wait for the controller's acknowledgement, start the plant, collect the N+1 samples of
/joint_states, rebuild the trial record (u and effort formed exactly as the controller did),
publish the summary, and compute the next feed-forward with the configured law. Live parameter
changes take effect at the next trial boundary. Stops after ``max_trials`` or once every joint
stayed within the bound ``stop_when_settled`` trials.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from enum import Enum

import numpy as np
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .. import topics
from ..core import schema
from ..core.config import Config
from ..core.experiment import Experiment, build_law
from ..core.laws import LearningLaw, TrialRecord
from ..core.loop import period_ns, record_from_samples, sample_index
from .cdr import CdrError, read_joint_state
from .common import (
    DIAGNOSTICS_QOS,
    EVENTS_QOS,
    LATCHED_QOS,
    SAMPLES_QOS,
    SchemaParameters,
    diagnostic_array,
    doubles,
    spin,
    status,
    values_of,
    wall_clock,
)

NAME = schema.SUPERVISOR
LEVEL_NAMES = ("M", "M'", "M''")
STEP_TIMEOUT = 30.0
RECORDER_TIMEOUT = 5.0
"""Wall seconds to wait for bag_recorder to catch up before going on without it."""
"""Wall seconds a protocol step may take before the trial is aborted and tried again."""


class Phase(Enum):
    """Where the supervisor is in the trial protocol."""

    WAIT_GRAPH = "wait_graph"
    RESETTING = "resetting"
    WAIT_ACK = "wait_ack"
    STARTING = "starting"
    RUNNING = "running"
    WAIT_RECORDER = "wait_recorder"
    FINISHED = "finished"


class IlcSupervisor(Node):
    """Trial orchestration and the learning law."""

    def __init__(self) -> None:
        super().__init__(NAME)
        self.params = SchemaParameters(self, NAME)
        self.active: Config = self.params.config
        self.experiment = Experiment(self.active)
        self.reference = self.experiment.reference
        self.law: LearningLaw = build_law(self.active)
        self.joint_names: list[str] = self.active["joint_names"]
        self.step_ns = period_ns(self.experiment.period)
        n_samples, n = self.reference.position.shape
        self.position = np.empty((n_samples, n))
        self.velocity = np.empty((n_samples, n))
        self.received = np.zeros(n_samples, dtype=bool)
        self.trial = 1
        self.feedforward = self.law.initial_feedforward(self.reference)
        self.levels: np.ndarray | None = None
        self.t0_ns = -1
        self.phase = Phase.WAIT_GRAPH
        self.phase_since = time.monotonic()
        self.within_streak = 0
        self.recorder_ready = False
        self.recorder_trials = 0
        self.recorder_lost = False
        """Trials bag_recorder has received completely (its status on /diagnostics)."""
        self.start_future: Future | None = None
        self.t0_ns_end = 0

        self.reset_client = self.create_client(Trigger, topics.RESET_SERVICE)
        self.start_client = self.create_client(Trigger, topics.START_SERVICE)
        self.feedforward_pub = self.create_publisher(JointTrajectory, topics.FEEDFORWARD,
                                                     LATCHED_QOS)
        self.events_pub = self.create_publisher(DiagnosticArray, topics.TRIAL_EVENTS, EVENTS_QOS)
        self.summary_pub = self.create_publisher(DiagnosticArray, topics.TRIAL_SUMMARY,
                                                 EVENTS_QOS)
        self.state_sub = self.create_subscription(JointState, topics.JOINT_STATES,
                                                  self.on_joint_state, SAMPLES_QOS, raw=True)
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self.on_diagnostics,
                                 DIAGNOSTICS_QOS)
        self.create_timer(0.1, self.on_timer, clock=wall_clock())
        self.get_logger().info(f"{self.active['law']} law, up to {self.active['max_trials']} "
                               "trials; waiting for the plant and the controller")

    # --- protocol steps -------------------------------------------------------------------
    def _enter(self, phase: Phase) -> None:
        self.phase = phase
        self.phase_since = time.monotonic()

    def on_timer(self) -> None:
        """Start once the plant is up; retry a refused start; abort a stuck step."""
        if self.phase is Phase.WAIT_GRAPH:
            if self.reset_client.service_is_ready() and self.start_client.service_is_ready() \
                    and self.state_sub.get_publisher_count() >= 1 and \
                    (self.recorder_ready or not self.active["wait_for_recorder"]):
                self._reset()
        elif self.phase is Phase.WAIT_RECORDER and \
                time.monotonic() - self.phase_since > RECORDER_TIMEOUT:
            self.get_logger().error(f"bag_recorder silent for {RECORDER_TIMEOUT:g} s; going "
                                    "on without waiting for it")
            self.recorder_lost = True
            self._reset()
        elif self.phase is not Phase.FINISHED and \
                time.monotonic() - self.phase_since > STEP_TIMEOUT:
            self.get_logger().error(f"trial {self.trial}: no progress in {self.phase.value} for "
                                    f"{STEP_TIMEOUT:g} s; aborting and trying the trial again")
            self._event("aborted", [("trial", str(self.trial)),
                                    ("phase", self.phase.value)])
            self._reset()
        elif self.phase is Phase.STARTING and self.start_future is None:
            self._start()

    def _reset(self) -> None:
        self._enter(Phase.RESETTING)
        self.t0_ns = -1
        future = self.reset_client.call_async(Trigger.Request())
        future.add_done_callback(self.on_reset_done)

    def on_reset_done(self, future: Future) -> None:
        """Plant at x_d(0): push this trial's feed-forward stamped with its t0."""
        response = future.result()
        if self.phase is not Phase.RESETTING or response is None:
            return
        if not response.success or not response.message.startswith(topics.T0_PREFIX):
            self.get_logger().error(f"plant reset failed: {response.message}")
            return
        self.t0_ns = int(response.message[len(topics.T0_PREFIX):])
        self.received[:] = False
        self._enter(Phase.WAIT_ACK)
        self.feedforward_pub.publish(self._feedforward_message())

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        """The controller's acknowledgement of this trial's feed-forward starts the trial."""
        for item in msg.status:
            if item.name == topics.RECORDER_STATUS and item.message == "ready":
                self.recorder_ready = True
                received = values_of(item).get("trials_received", "0")
                self.recorder_trials = max(self.recorder_trials,
                                           int(received) if received.isdigit() else 0)
        if self.phase is Phase.WAIT_RECORDER and self.recorder_trials >= self.trial - 1:
            self._reset()
            return
        if self.phase is not Phase.WAIT_ACK:
            return
        for item in msg.status:
            if item.name != topics.FEEDFORWARD_ACK_STATUS:
                continue
            values = values_of(item)
            if values.get("trial") == str(self.trial) and \
                    values.get("t0_ns") == str(self.t0_ns):
                self._event("start", [("trial", str(self.trial))], self.t0_ns)
                self._enter(Phase.STARTING)
                self._start()
                return

    def _start(self) -> None:
        future = self.start_client.call_async(Trigger.Request())
        self.start_future = future
        future.add_done_callback(self.on_start_done)

    def on_start_done(self, future: Future) -> None:
        """Running, or refused (not linked yet): retried by the timer."""
        self.start_future = None
        response = future.result()
        if self.phase is not Phase.STARTING or response is None:
            return
        if response.success:
            self.phase = Phase.RUNNING
        else:
            self.get_logger().info(f"plant refused start: {response.message}; retrying",
                                   throttle_duration_sec=2.0)

    def on_joint_state(self, raw: bytes) -> None:
        """Keep the samples of the current trial; the last one ends it."""
        if self.t0_ns < 0:
            return
        try:
            stamp, position, velocity = read_joint_state(raw)
        except CdrError as exc:
            self.get_logger().error(f"bad joint state ignored: {exc}", throttle_duration_sec=5.0)
            return
        i = sample_index(stamp, self.t0_ns, self.step_ns, self.received.shape[0])
        if i is None or self.received[i]:
            return
        self.position[i] = position
        self.velocity[i] = velocity
        self.received[i] = True
        self.phase_since = time.monotonic()  # progress: a slow real-time trial is not stuck
        if i == self.received.shape[0] - 1:
            if not self.received.all():
                missing = int((~self.received).sum())
                self.get_logger().error(f"trial {self.trial}: {missing} samples lost; retrying")
                self._event("aborted", [("trial", str(self.trial)), ("lost", str(missing))])
                self._reset()
                return
            self._end_trial()

    def _end_trial(self) -> None:
        self.t0_ns_end = self.t0_ns + (self.received.shape[0] - 1) * self.step_ns
        self.t0_ns = -1
        record = record_from_samples(self.experiment, self.trial, self.feedforward,
                                     self.position, self.velocity, self.levels, self.reference)
        summary = self._summary(record)
        self.summary_pub.publish(diagnostic_array(self, [summary], self.t0_ns_end))
        self._event("end", [(kv.key, kv.value) for kv in summary.values], self.t0_ns_end)
        bound = self.active["error_bound"]
        within = bool(np.all(record.max_abs_error <= bound))
        self.within_streak = self.within_streak + 1 if within else 0
        settled = self.active["stop_when_settled"]
        if self.trial >= self.active["max_trials"] or \
                (settled > 0 and self.within_streak >= settled):
            self._enter(Phase.FINISHED)
            self._event("finished", [("trials", str(self.trial))], self.t0_ns_end)
            self.get_logger().info(f"finished after {self.trial} trials")
            return
        if self.params.pending is not self.active:  # the trial boundary: live changes apply
            self.active = self.params.pending
            self.law = build_law(self.active)
            self.get_logger().info(f"parameters changed; applied from trial {self.trial + 1}")
        update = self.law.update(record)
        self.feedforward = update.feedforward
        self.levels = update.levels
        self.trial += 1
        if self.active["wait_for_recorder"] and not self.recorder_lost and \
                self.recorder_trials < self.trial - 1:
            self._enter(Phase.WAIT_RECORDER)  # bag_recorder lags: let it catch up first
        else:
            self._reset()

    # --- messages -------------------------------------------------------------------------
    def _feedforward_message(self) -> JointTrajectory:
        ref = self.reference
        msg = JointTrajectory()
        msg.header.frame_id = f"{topics.FEEDFORWARD_FRAME_PREFIX}{self.trial}"
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self.t0_ns, 1_000_000_000)
        msg.joint_names = self.joint_names
        points = []
        for i in range(ref.samples):
            sec, nanosec = divmod(i * self.step_ns, 1_000_000_000)
            points.append(JointTrajectoryPoint(
                positions=doubles(ref.position[i]), velocities=doubles(ref.velocity[i]),
                accelerations=doubles(self.feedforward[i]),
                time_from_start=Duration(sec=sec, nanosec=nanosec)))
        msg.points = points
        return msg

    def _summary(self, record: TrialRecord) -> DiagnosticStatus:
        bound = self.active["error_bound"]
        max_error = record.max_abs_error
        values = [("trial", str(record.trial)),
                  ("mass_uncertainty", repr(self.experiment.mass_uncertainty)),
                  ("law", str(self.active["law"]))]
        tables = {"max_abs_error": max_error,
                  "max_abs_feedforward": np.max(np.abs(record.feedforward), axis=0),
                  "max_abs_effort": np.max(np.abs(record.effort), axis=0)}
        for key, row in tables.items():
            values += [(f"{key}/{name}", repr(float(x)))
                       for name, x in zip(self.joint_names, row, strict=True)]
        if record.levels is not None:
            for symbol, row in zip(LEVEL_NAMES, record.levels, strict=True):
                values += [(f"level/{symbol}/{name}", repr(float(x)))
                           for name, x in zip(self.joint_names, row, strict=True)]
        level = DiagnosticStatus.OK if np.all(max_error <= bound) else DiagnosticStatus.WARN
        return status(topics.SUMMARY_STATUS, f"trial {record.trial}", values, level, NAME)

    def _event(self, message: str, values: Sequence[tuple[str, str]],
               stamp: int | None = None) -> None:
        event = status(topics.TRIAL_STATUS, message, values, hardware_id=NAME)
        self.events_pub.publish(diagnostic_array(self, [event], stamp))


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros ilc_supervisor``."""
    return spin(IlcSupervisor, args)


if __name__ == "__main__":
    raise SystemExit(main())
