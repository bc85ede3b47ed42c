"""ilc_supervisor: runs the trials and learns between them.

Per trial: reset the plant (learning its t0), push the feed-forward (latched /ilc/feedforward),
wait for the controller's acknowledgement, start the plant, collect the N+1 samples of
/joint_states, rebuild the trial record (u and effort formed exactly as the controller did),
publish the summary, and compute the next feed-forward with the configured law. Live parameter
changes take effect at the next trial boundary. Stops after ``max_trials`` or once every joint
stayed within the bound ``stop_when_settled`` trials.

A trial ends when all its samples are in *and* the controller reported it ``done``: a trial the
controller aborted (error envelope) is rebuilt with the safe hold from the abort sample, marked
(``aborted`` event, ``aborted_at`` in the summary) and not learned from: the next trial reuses
its feed-forward, exactly as ``run_trials`` in-process. A trial with a watchdog trip is run
again. With ``store.directory`` every accepted trial and the feed-forward it led to are saved
(core.store.RunStore, atomic) before the next trial starts; with ``store.resume`` the run
continues after the last stored trial. With ``wait_for_recorder`` a trial is stored only once
bag_recorder filed it; the next trial is prepared meanwhile (plant reset, feed-forward pushed
and acknowledged) and started after the store (WAIT_RECORDER). Invalid /joint_states are
rejected and counted.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from enum import Enum

import numpy as np
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .. import topics
from ..core import schema
from ..core.config import Config
from ..core.errors import ExoIlcError
from ..core.experiment import Experiment, build_law
from ..core.laws import FeedforwardUpdate, LearningLaw, TrialRecord
from ..core.loop import period_ns, record_from_samples, sample_index
from ..core.store import RunStore
from ..core.validation import Rejection, check_feedforward_array
from .common import (
    DIAGNOSTICS_QOS,
    EVENTS_QOS,
    LATCHED_QOS,
    Inbox,
    SchemaParameters,
    diagnostic_array,
    doubles,
    spin,
    status,
    values_of,
    wall_clock,
)
from .guard import Health, JointStateGate, Rejections, rejections_check

NAME = schema.SUPERVISOR
STEP_TIMEOUT = 30.0
"""Wall seconds a protocol step may take before the trial is aborted and tried again."""
RECORDER_TIMEOUT = 5.0
"""Wall seconds to wait for bag_recorder to file a trial before going on without it."""


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
        """Trials bag_recorder has received completely (its status on /diagnostics)."""
        self.recorder_lost = False
        self.unsaved: tuple[TrialRecord, FeedforwardUpdate, Config] | None = None
        """The ended trial waiting for bag_recorder to file it before it is stored (with the
        configuration it ran with); the next trial is prepared meanwhile but not started."""
        self.unsaved_since = 0.0
        self.after_save: str | None = None
        """In WAIT_RECORDER: ``start`` (the next trial is acknowledged) or ``finish``."""
        self.start_future: Future | None = None
        self.t0_ns_end = 0
        self.rejections = Rejections(self)
        self.gate = JointStateGate(self.joint_names, self.rejections)
        self.done_report: dict[str, str] | None = None
        """The controller's ``done`` of the current trial (abort index, watchdog trips)."""
        self.aborted_trials: list[int] = []
        self.retried: list[tuple[int, str]] = []
        self.error: str | None = None
        self.exit_code: int | None = None
        """Set when the node must stop (read by common.spin)."""
        self.plant_values: dict[str, object] | None = None
        self.plant_future: Future | None = None
        self.store: RunStore | None = None
        self.ready = False
        """Store opened (or none) and the starting trial known."""

        self.reset_client = self.create_client(Trigger, topics.RESET_SERVICE)
        self.start_client = self.create_client(Trigger, topics.START_SERVICE)
        self.feedforward_pub = self.create_publisher(JointTrajectory, topics.FEEDFORWARD,
                                                     LATCHED_QOS)
        self.events_pub = self.create_publisher(DiagnosticArray, topics.TRIAL_EVENTS, EVENTS_QOS)
        self.summary_pub = self.create_publisher(DiagnosticArray, topics.TRIAL_SUMMARY,
                                                 EVENTS_QOS)
        self.inbox = Inbox(self)  # the trial's samples, drained in batches (see Inbox)
        self.state_sub = self.inbox.subscribe(JointState, topics.JOINT_STATES)
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self.on_diagnostics,
                                 DIAGNOSTICS_QOS)
        self.create_timer(0.1, self.on_timer, clock=wall_clock())
        self.plant_params = AsyncParameterClient(self, schema.PLANT)
        self.health = Health(self, NAME)
        self.health.checks += [self._run_check, rejections_check(self.rejections,
                                                                 "/joint_states")]
        self.health_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                                DIAGNOSTICS_QOS)
        self.create_timer(1.0, self.on_health_timer, clock=wall_clock())
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
                if not self.ready:
                    self._prepare()
                    return
                self._reset()
        elif self.unsaved is not None and \
                time.monotonic() - self.unsaved_since > RECORDER_TIMEOUT:
            self.get_logger().error(f"bag_recorder silent for {RECORDER_TIMEOUT:g} s; going "
                                    "on without waiting for it")
            self.recorder_lost = True
            self._store_unsaved()
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
        self.done_report = None
        self.gate.restart()
        self._enter(Phase.WAIT_ACK)
        self.feedforward_pub.publish(self._feedforward_message())

    def poll(self) -> None:
        """Every /joint_states message waiting in the inbox (called by the spin loop)."""
        for _, _, raw in self.inbox.take():
            self.on_joint_state(raw)

    def destroy_node(self) -> None:
        """The inbox's companion node, then this one."""
        self.inbox.destroy()
        super().destroy_node()

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        """The controller's acknowledgement of this trial's feed-forward starts the trial;
        its ``done`` ends it once every sample is in (the inbox is drained first)."""
        self.poll()
        for item in msg.status:
            if item.name == topics.RECORDER_STATUS and item.message == "ready":
                self.recorder_ready = True
                received = values_of(item).get("trials_received", "0")
                self.recorder_trials = max(self.recorder_trials,
                                           int(received) if received.isdigit() else 0)
        if self.unsaved is not None and self.recorder_trials >= self.unsaved[0].trial:
            self._store_unsaved()
            return
        if self.phase is Phase.RUNNING:
            for item in msg.status:
                if item.name == topics.CONTROLLER_TRIAL_STATUS and item.message == "done":
                    values = values_of(item)
                    if values.get("trial") == str(self.trial) and \
                            values.get("t0_ns") == str(self.t0_ns):
                        self.done_report = values
                        self._maybe_end_trial()
            return
        if self.phase is not Phase.WAIT_ACK:
            return
        for item in msg.status:
            if item.name != topics.FEEDFORWARD_ACK_STATUS:
                continue
            values = values_of(item)
            if values.get("trial") == str(self.trial) and \
                    values.get("t0_ns") == str(self.t0_ns):
                if self.unsaved is not None:  # the previous trial is not in the bag yet
                    self.after_save = "start"
                    self._enter(Phase.WAIT_RECORDER)
                    return
                self._begin_trial()
                return

    def _begin_trial(self) -> None:
        self._event("start", [("trial", str(self.trial))], self.t0_ns)
        self._enter(Phase.STARTING)
        self._start()

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
        """Keep the samples of the current trial; the last one (with the controller's
        ``done``) ends it. Every message is checked (bad input is counted even between
        trials); only the current trial's samples are kept."""
        sample = self.gate(raw)
        if sample is None or self.t0_ns < 0:
            return
        stamp, position, velocity = sample
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
                self._retry("lost", [("lost", str(missing))])
                return
            self._maybe_end_trial()

    def _maybe_end_trial(self) -> None:
        report = self.done_report
        if self.t0_ns < 0 or report is None or not self.received[-1]:
            return
        trips = int(report.get("watchdog_trips", "0"))
        if trips:
            self.get_logger().error(f"trial {self.trial}: the controller's watchdog tripped "
                                    f"{trips}x (safe hold); running the trial again")
            self._retry("watchdog", [("watchdog_trips", str(trips))])
            return
        self._end_trial()

    def _retry(self, reason: str, values: Sequence[tuple[str, str]]) -> None:
        self.retried.append((self.trial, reason))
        self._event("aborted", [("trial", str(self.trial)), ("reason", reason), *values])
        self._reset()

    def _end_trial(self) -> None:
        assert self.done_report is not None
        aborted = int(self.done_report.get("aborted_at", "-1"))
        self.t0_ns_end = self.t0_ns + (self.received.shape[0] - 1) * self.step_ns
        self.t0_ns = -1
        record = record_from_samples(self.experiment, self.trial, self.feedforward,
                                     self.position, self.velocity, self.levels, self.reference,
                                     aborted if aborted >= 0 else None)
        if record.aborted:  # nothing learned from it: the next trial reuses its feed-forward
            self.aborted_trials.append(self.trial)
            self.get_logger().error(f"trial {self.trial} aborted by the error envelope at "
                                    f"sample {aborted}; not learned from")
            update = FeedforwardUpdate(self.feedforward, self.levels)
        else:
            if self.params.pending is not self.active:  # the trial boundary: changes apply
                self._apply_pending()
            update = self.law.update(record)
            checked = check_feedforward_array(update.feedforward, self.feedforward.shape,
                                              "learned feed-forward")
            if isinstance(checked, Rejection):
                self._fail(f"trial {self.trial}: the learning law produced a bad feed-forward "
                           f"({checked}); it was not stored or used")
                return
        summary = self._summary(record)
        if record.aborted:
            self._event("aborted", [("trial", str(self.trial)), ("reason", "error_envelope"),
                                    ("aborted_at", str(aborted))], self.t0_ns_end)
        self.summary_pub.publish(diagnostic_array(self, [summary], self.t0_ns_end))
        self._event("end", [(kv.key, kv.value) for kv in summary.values], self.t0_ns_end)
        self.unsaved = (record, update, self._store_config())
        self.unsaved_since = time.monotonic()
        if not (self.active["wait_for_recorder"] and not self.recorder_lost and
                self.recorder_trials < self.trial) and not self._save_trial():
            return
        # With a recorder the trial is stored only once the bag holds it too; the next trial
        # is prepared meanwhile (plant reset, feed-forward pushed) and starts after the store.
        self._after_trial(record, update)

    def _save_trial(self) -> bool:
        """The ended trial into the store (False: it could not be saved; the run stopped).
        With ``wait_for_recorder`` this runs only after bag_recorder filed the trial, so a
        stored trial is always in a bag: if the recorder dies first, the trial is not stored
        and a resume runs it again."""
        assert self.unsaved is not None
        record, update, config = self.unsaved
        trial, self.unsaved = record.trial, None
        if self.store is not None:
            try:
                self.store.save(record, update, config)
            except (ExoIlcError, OSError) as exc:
                self._fail(f"trial {trial}: cannot save to the store: {exc}", trial - 1)
                return False
        return True

    def _store_unsaved(self) -> None:
        """The recorder filed the waiting trial (or went silent): store it, then start the
        next trial or finish if that was waiting for it."""
        if not self._save_trial() or self.phase is not Phase.WAIT_RECORDER:
            return
        if self.after_save == "finish":
            self._finish(self.trial)
        else:
            self._begin_trial()

    def _after_trial(self, record: TrialRecord, update: FeedforwardUpdate) -> None:
        bound = self.active["error_bound"]
        within = bool(np.all(record.max_abs_error <= bound)) and not record.aborted
        self.within_streak = self.within_streak + 1 if within else 0
        settled = self.active["stop_when_settled"]
        if self.trial >= self.active["max_trials"] or \
                (settled > 0 and self.within_streak >= settled):
            if self.unsaved is not None:  # finished once the last trial is stored
                self.after_save = "finish"
                self._enter(Phase.WAIT_RECORDER)
            else:
                self._finish(self.trial)
            return
        if self.params.pending is not self.active:  # the trial boundary: live changes apply
            self._apply_pending()
        self.feedforward = update.feedforward
        self.levels = update.levels
        self.trial += 1
        self._reset()

    def _apply_pending(self) -> None:
        self.active = self.params.pending
        self.law = build_law(self.active)
        self.get_logger().info(f"parameters changed; applied from trial {self.trial + 1}")

    # --- store and start-up ---------------------------------------------------------------
    def _store_config(self) -> Config:
        """The supervisor's configuration with the plant's parameters (the store's key
        covers the plant: mass uncertainty, integration)."""
        if not self.plant_values:
            return self.active
        return self.active.replace(self.plant_values)

    def _prepare(self) -> None:
        """Before trial 1: the plant's parameters (for the store key), then the store."""
        if not self.active["store.directory"]:
            self.ready = True
            return
        if self.plant_future is None:
            names = [p.name for p in schema.PARAMETERS if p.section == schema.PLANT]
            if not self.plant_params.services_are_ready():
                return
            self.plant_future = self.plant_params.get_parameters(names)
            return
        if not self.plant_future.done():
            return
        result = self.plant_future.result()
        names = [p.name for p in schema.PARAMETERS if p.section == schema.PLANT]
        if result is None or len(result.values) != len(names):
            self.plant_future = None  # try again
            return
        self.plant_values = {n: parameter_value_to_python(v)
                             for n, v in zip(names, result.values, strict=True)}
        try:
            self._open_store()
        except ExoIlcError as exc:
            self._fail(str(exc), code=2)
            return
        self.ready = True

    def _open_store(self) -> None:
        config = self._store_config()
        self.experiment = Experiment(config)
        store = RunStore(self.active["store.directory"], config, self.reference)
        if store.completed and not self.active["store.resume"]:
            raise ExoIlcError(f"store {store.directory} already holds {store.completed} trials "
                              "of this run; resume it (store.resume / exo-ilc run --resume) or "
                              "use another store")
        self.store = store
        if not store.completed:
            self.get_logger().info(f"saving every trial to {store.directory}")
            return
        stored = store.load()
        bound = self.active["error_bound"]
        for item in stored:
            within = bool(np.all(item.record.max_abs_error <= bound)) and \
                not item.record.aborted
            self.within_streak = self.within_streak + 1 if within else 0
            if item.record.aborted:
                self.aborted_trials.append(item.record.trial)
        last = stored[-1]
        self.feedforward = last.next_update.feedforward
        self.levels = last.next_update.levels
        self.trial = last.record.trial + 1
        self.get_logger().info(f"resumed from {store.directory}: trials 1..{last.record.trial} "
                               f"restored, continuing with trial {self.trial}")
        self._event("resumed", [("trials", str(last.record.trial))])
        settled = self.active["stop_when_settled"]
        if last.record.trial >= self.active["max_trials"] or \
                (settled > 0 and self.within_streak >= settled):
            self._finish(last.record.trial)

    def _finish(self, trials: int, values: Sequence[tuple[str, str]] = ()) -> None:
        self._enter(Phase.FINISHED)
        self._event("finished", [("trials", str(trials)), *values], self.t0_ns_end or None)
        self.get_logger().info(f"finished after {trials} trials")

    def _fail(self, message: str, completed: int | None = None, code: int = 1) -> None:
        """Stop running trials: ERROR on /diagnostics, ``finished`` with the error after
        ``completed`` trials (default: those before the current one)."""
        self.error = message
        self.get_logger().error(message)
        self._finish(self.trial - 1 if completed is None else completed,
                     [("error", message)])
        self.on_health_timer()
        self.exit_code = code

    def on_health_timer(self) -> None:
        """Health on /diagnostics."""
        self.health_pub.publish(diagnostic_array(self, [self.health.status()]))

    def _run_check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        values = [("trial", str(self.trial)), ("phase", self.phase.value),
                  ("aborted_trials", " ".join(map(str, self.aborted_trials))),
                  ("retried", " ".join(f"{k}:{why}" for k, why in self.retried)),
                  ("store", "" if self.store is None else str(self.store.directory)),
                  ("stored_trials", "0" if self.store is None else str(self.store.completed))]
        if self.error:
            return DiagnosticStatus.ERROR, self.error, values
        reasons = []
        if self.aborted_trials:
            reasons.append(f"trials aborted by the error envelope: {self.aborted_trials}")
        if self.retried:
            reasons.append(f"{len(self.retried)} trials run again")
        level = DiagnosticStatus.WARN if reasons else DiagnosticStatus.OK
        return level, "; ".join(reasons), values

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
            for symbol, row in zip(topics.LEVEL_SYMBOLS, record.levels, strict=True):
                values += [(f"level/{symbol}/{name}", repr(float(x)))
                           for name, x in zip(self.joint_names, row, strict=True)]
        if record.aborted:
            values.append(("aborted_at", str(record.aborted_at)))
        level = DiagnosticStatus.OK if np.all(max_error <= bound) and not record.aborted \
            else DiagnosticStatus.WARN
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
