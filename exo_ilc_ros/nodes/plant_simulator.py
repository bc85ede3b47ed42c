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

A state that stops being finite (the plant diverged: a joint damping too stiff even for the
sub-steps, a non-finite model) stops the trial at that sample, as the in-process trial kernel
does: no sample of it goes out; ``diverged`` on /diagnostics names the sample's stamp, the joint
and the cause (:func:`exo_ilc_ros.core.loop.divergence.state_divergence`, the in-process
report's rule), and the supervisor ends the trial there. The node runs on; the next reset puts
the arm back at x_d(0).

A person strapped in (``musculoskeletal.model``): every sample's cuff wrenches go out on
``/cuffs/<cuff>/wrench`` (``geometry_msgs/WrenchStamped``, stamped as the sample, just before
its /joint_states), and the person's own joints on ``/person/joint_states`` (just before
the sample's /joint_states too); the person's display URDF
(:func:`~exo_ilc_ros.core.person.display.person_urdf`) goes out once on
``/person/robot_description`` (transient local), so a view draws the person where the
simulation has it. The first sample of a trial at which a cuff presses past
``safety.cuff_force_limit`` (:func:`~exo_ilc_ros.core.person.cuffs.beyond_cuff_limit`, the
in-process rule), the error envelope not left before, latches the controller's safe hold
around the pose of that sample: from that sample on the plant applies the hold (the same
kernel and ramp as the controller's, so the arm moves as in-process) instead of the commands,
until the next trial; the supervisor sees the same sample in the wrenches and rebuilds the
record with the hold from it.
"""

from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rclpy.timer import Timer
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from ..core.arm.build import view_urdf
from ..core.loop.controller import outside_envelope
from ..core.loop.divergence import state_divergence
from ..core.loop.plant import clamp_counted, finite_state
from ..core.loop.safety import LateCommands
from ..core.person.cuffs import beyond_cuff_limit
from ..core.person.experiment import StrappedExperiment
from ..wire import topics
from ..wire.cdr import JointStateWriter
from ..wire.protocol import trial_of_frame
from ..wire.publishers import max_bytes
from .common import LATCHED_QOS, SAMPLES_QOS, CountingPublisher, spin, wall_clock
from .diagnostics import diagnostic_array, stamp_ns, status
from .plant_base import NAME, Pace, PlantNode
from .realtime import plant_scheduling
from .sender_check import (
    FEEDFORWARD_READER_QOS,
    TrustedInput,
    decodes,
    deserializing_callback,
)


class PlantSimulator(PlantNode):
    """The simulated exoskeleton arm (true masses, ``mass_uncertainty``)."""

    def __init__(self) -> None:
        super().__init__(self.on_command)
        config = self.params.config
        self.stepper = self.experiment.make_stepper()
        self.last_index = self.experiment.reference.samples - 1
        self.now_ns = 0
        self.t0_ns = 0
        self.index = 0
        self.armed = False
        self.running = False
        self.unapplied = np.zeros(config.joints)
        """Lock-step: where a command received between trials is clamped (never applied)."""
        self.timer: Timer | None = None
        self.late = LateCommands()  # real time: periods run on a late (held) command
        self.patient = self.experiment.patient
        self.next_trial: tuple[int, int] | None = None
        """(trial k, t0) of the last /ilc/feedforward: the patient's draws are trial k's."""
        self.before = (np.empty(config.joints), np.empty(config.joints))
        """The true state at the sample before the one being stepped to (for a divergence)."""
        self.truth = JointStateWriter(config["joint_names"])
        self.truth_pub = self.create_publisher(
            JointState, topics.TRUE_JOINT_STATES, SAMPLES_QOS,
            publisher_class=CountingPublisher) if self.patient.measures else None
        self.feedforward_sub = TrustedInput(  # the supervisor's profiles only: their trial
            self, JointTrajectory, topics.FEEDFORWARD, FEEDFORWARD_READER_QOS,
            deserializing_callback(JointTrajectory, self.on_feedforward, self.rejections,
                                   topics.FEEDFORWARD),
            self.rejections, max_bytes(topics.FEEDFORWARD, config.joints,
                                       self.experiment.reference.position.shape[0]),
            decodes(JointTrajectory, self.rejections, topics.FEEDFORWARD)) \
            if self.patient.enabled else None
        self.person = self.experiment.arm \
            if isinstance(self.experiment, StrappedExperiment) else None
        """A person strapped in: the strapped model this node steps (its cuffs' wrench)."""
        self.cuff_pubs = [self.create_publisher(WrenchStamped, topic, SAMPLES_QOS,
                                                publisher_class=CountingPublisher)
                          for topic in topics.CUFF_WRENCHES] if self.person is not None else []
        """A person strapped in: each cuff's wrench per sample (empty: no person)."""
        self.person_state = JointStateWriter(self.person.person_joint_names()) \
            if self.person is not None else None
        """A person strapped in: the person's joints per sample (/person/joint_states)."""
        self.person_pub = self.create_publisher(
            JointState, topics.PERSON_JOINT_STATES, SAMPLES_QOS,
            publisher_class=CountingPublisher) if self.person is not None else None
        self.not_given = np.full(len(self.person.person_joint_names()), np.nan) \
            if self.person is not None else None
        if self.person is not None:  # the person's display URDF, once, latched
            description = String(data=self.person.person_description(view_urdf(config)[2]))
            self.description_pub = self.create_publisher(
                String, topics.PERSON_DESCRIPTION, LATCHED_QOS,
                publisher_class=CountingPublisher)
            self.description_pub.publish(description)
        self.cuff_msgs = [WrenchStamped() for _ in self.cuff_pubs]
        for msg, frame in zip(self.cuff_msgs, topics.CUFF_FRAMES, strict=False):
            msg.header.frame_id = frame
        self.cuff_limit = [float(x) for x in config["safety.cuff_force_limit"]]
        self.guarded = False
        """The running trial left the error envelope or pressed past the cuff-force limit
        (no further cuff check: the in-process rule checks only until the first abort)."""
        self.create_service(Trigger, topics.RESET_SERVICE, self.on_reset)
        self.create_service(Trigger, topics.START_SERVICE, self.on_start)
        self.pace = Pace(float(config["pace"]) if self.lock_step else 0.0)
        """Lock-step: simulated s per wall s at most, from each trial's sample 0."""
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
        finite_state(self.stepper.position, self.stepper.velocity)  # compiled now too
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
        self.hold_reason = PlantNode.hold_reason
        self.guarded = False
        self.diverged = None
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
        self.pace.start(self.t0_ns)
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
        effort = self.command_of(raw)
        if effort is None:
            return
        if effort.shape != self.held.shape:
            self.reject_effort(effort)
            return
        if self.lock_step and self.running:  # the hot path: check, count, clamp, step at once
            self._keep_state()
            if self.hold_pose is not None:  # a cuff pressed past its limit: the safe hold
                effort = self.safe_hold.hold(self.stepper.position, self.stepper.velocity)
            beyond = self.stepper.step(effort, self.saturated)
        else:  # real time: the command to hold; lock-step between trials: only checked
            beyond = clamp_counted(effort, self.limit, self.saturated,
                                   self.unapplied if self.lock_step else self.held)
        if beyond < 0:
            self.reject_effort(effort)
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

    def on_tick(self) -> None:
        """Real-time mode: one period with the held command (the safe hold after a trip)."""
        if not self.running:
            return
        if self.watchdog.check(time.monotonic_ns()) or \
                (self.watchdog.tripped and self.hold_pose is None):
            self.latch_safe_hold(self.stepper.position, "stopped holding the last command; "
                                 "safe hold around the current pose until the next trial")
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

    def effort_values(self) -> list[tuple[str, str]]:
        """The real-time plant's late commands and the scheduler, on its health."""
        return [*self.late.as_values(), ("scheduler", self.scheduler)]

    def _advance(self, effort: np.ndarray) -> None:
        self._keep_state()
        self.stepper.step(effort)
        self._stepped()

    def _keep_state(self) -> None:
        np.copyto(self.before[0], self.stepper.position)
        np.copyto(self.before[1], self.stepper.velocity)

    def _stepped(self) -> None:
        self.index += 1
        self.now_ns += self.step_ns
        if not finite_state(self.stepper.position, self.stepper.velocity):
            self._diverged()
            return
        self.pace.wait(self.now_ns)
        self._publish()
        if self.index >= self.last_index:
            self._stop()

    def _diverged(self) -> None:
        """The state at this sample is not finite: the trial stops here, reported (not sent)."""
        self._stop()
        trial = self.next_trial[0] if self.next_trial is not None else 0
        self.report_divergence(state_divergence(
            self.experiment, trial, self.index, self.before[0], self.before[1],
            self.params.config["joint_names"]), self.now_ns, self.t0_ns)

    def _stop(self) -> None:
        self.running = False
        self.watchdog.disarm()
        if self.timer is not None:
            self.timer.cancel()

    def _publish(self) -> None:
        stepper = self.stepper
        position, velocity = stepper.measure()
        if self.person is not None:
            self._cuffs(self.person.wrench, position)
            if self.person_pub is not None and self.person_state is not None and \
                    self.not_given is not None:
                self.person_pub.publish(self.person_state.write(
                    self.now_ns, self.person.person_qpos(), self.person.person_qvel(),
                    self.not_given))
        self.state_pub.publish(self.state.write(self.now_ns, position, velocity,
                                                stepper.applied))
        if self.truth_pub is not None:
            self.truth_pub.publish(self.truth.write(self.now_ns, stepper.position,
                                                    stepper.velocity, stepper.applied))
        if self.index % self.clock_every and self.index < self.last_index:
            return  # /clock at every clock_every-th sample, the first and the last
        self.publish_clock(self.now_ns)

    def _cuffs(self, wrench: np.ndarray, position: np.ndarray) -> None:
        """The cuffs' wrenches at this sample; the cuff-force limit (module docstring)."""
        sec, nanosec = divmod(self.now_ns, 1_000_000_000)
        for c, (pub, msg) in enumerate(zip(self.cuff_pubs, self.cuff_msgs, strict=True)):
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
            f, t = msg.wrench.force, msg.wrench.torque
            f.x, f.y, f.z, t.x, t.y, t.z = (float(x) for x in wrench[c])
            pub.publish(msg)
        if not self.running or self.guarded:
            return
        if outside_envelope(self.experiment.reference.position[self.index], position,
                            self.experiment.error_envelope):
            self.guarded = True  # the controller aborted here: its hold, not the plant's
            return
        cuff = beyond_cuff_limit(wrench, self.cuff_limit)
        if cuff < 0:
            return
        self.guarded = True
        self.hold_pose = np.array(position)
        self.safe_hold.hold_at(self.hold_pose)
        self.hold_reason = (f"{topics.CUFF_FRAMES[cuff]} pressed past "
                            f"safety.cuff_force_limit ({self.cuff_limit[cuff]:g} N); safe hold")
        self.get_logger().error(
            f"sample {self.index}: the {topics.CUFF_FRAMES[cuff]} pressed "
            f"{float(np.linalg.norm(wrench[cuff, :3])):.1f} N into the person, more than "
            f"safety.cuff_force_limit {self.cuff_limit[cuff]:g} N: trial aborted, safe hold "
            "around this pose until the next trial")
        self.on_health_timer()


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros plant_simulator``."""
    return spin(PlantSimulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
