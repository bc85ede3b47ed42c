"""ilc_supervisor: runs the trials of a :class:`core.session.LearningSession` through the graph.

Per trial: reset the plant (learning its t0), push the session's feed-forward (latched
/ilc/feedforward), wait for the controller's acknowledgement, start the plant, collect the N+1
samples of /joint_states, rebuild the trial record (u and effort formed exactly as the
controller did), publish the summary and conclude the trial in the session, which learns the
next feed-forward and decides when the run is finished. Every learning rule (envelope aborts,
live changes at the boundary, the settled streak, resume) is the session's; this node turns
messages and services into calls on it.

A trial with a watchdog trip, lost samples or a protocol step that made no progress for
``STEP_TIMEOUT`` is discarded and run again. Before trial 1 the plant's parameters are read
(mass uncertainty, integration: they label the summaries and key the store). With
``store.directory`` every concluded trial is saved (core.store.RunStore, atomic) before the next
one starts; with ``store.resume`` the run continues after the last stored trial. With
``wait_for_recorder`` a trial is stored only once bag_recorder filed it; the next trial is
prepared meanwhile (plant reset, feed-forward acknowledged) and started after the store
(WAIT_RECORDER).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from enum import Enum

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from .. import topics
from ..core import schema
from ..core.config import Config
from ..core.errors import ExoIlcError
from ..core.experiment import Experiment, build_reference
from ..core.loop import record_from_samples
from ..core.samples import TrialSamples
from ..core.session import LIVE, LearningSession, TrialConclusion
from ..core.store import RunStore
from .common import (
    DIAGNOSTICS_QOS,
    EVENTS_QOS,
    LATCHED_QOS,
    Inbox,
    SchemaParameters,
    diagnostic_array,
    spin,
    status,
    values_of,
    wall_clock,
)
from .guard import Health, JointStateGate, Rejections, rejections_check
from .protocol import feedforward_message, trial_summary

NAME = schema.SUPERVISOR
STEP_TIMEOUT = 30.0
"""Wall seconds a protocol step may take before the trial is discarded and run again."""
RECORDER_TIMEOUT = 5.0
"""Wall seconds to wait for bag_recorder to file a trial before going on without it."""
PLANT_PARAMETERS = [p.name for p in schema.PARAMETERS if p.section == schema.PLANT]


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
    """Trial orchestration over a learning session."""

    def __init__(self) -> None:
        super().__init__(NAME)
        self.params = SchemaParameters(self, NAME)
        self.seen = self.params.config
        """The parameters last handed to the session (live changes are the difference)."""
        config = self.params.config
        self.joint_names: list[str] = config["joint_names"]
        self.reference = build_reference(config)
        self.samples = TrialSamples(self.reference)
        self.session: LearningSession | None = None
        """Created once the plant's parameters are known (before trial 1)."""
        self.experiment: Experiment | None = None
        self.store: RunStore | None = None
        self.plant_future: Future | None = None
        self.phase = Phase.WAIT_GRAPH
        self.phase_since = time.monotonic()
        self.t0_ns_end = 0
        self.done_report: dict[str, str] | None = None
        """The controller's ``done`` of the current trial (abort index, watchdog trips)."""
        self.start_future: Future | None = None
        self.recorder_ready = False
        self.recorder_filed = 0
        """Trials bag_recorder has filed (its status on /diagnostics)."""
        self.recorder_lost = False
        self.unsaved: TrialConclusion | None = None
        """The concluded trial waiting for bag_recorder to file it before it is stored."""
        self.unsaved_since = 0.0
        self.after_save: str | None = None
        """In WAIT_RECORDER: ``start`` (the next trial is acknowledged) or ``finish``."""
        self.error: str | None = None
        self.exit_code: int | None = None
        """Set when the node must stop (read by common.spin)."""

        self.reset_client = self.create_client(Trigger, topics.RESET_SERVICE)
        self.start_client = self.create_client(Trigger, topics.START_SERVICE)
        self.plant_params = AsyncParameterClient(self, schema.PLANT)
        self.feedforward_pub = self.create_publisher(JointTrajectory, topics.FEEDFORWARD,
                                                     LATCHED_QOS)
        self.events_pub = self.create_publisher(DiagnosticArray, topics.TRIAL_EVENTS, EVENTS_QOS)
        self.summary_pub = self.create_publisher(DiagnosticArray, topics.TRIAL_SUMMARY,
                                                 EVENTS_QOS)
        self.health_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                                DIAGNOSTICS_QOS)
        self.inbox = Inbox(self)  # the trial's samples, drained in batches (see Inbox)
        self.state_sub = self.inbox.subscribe(JointState, topics.JOINT_STATES)
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self.on_diagnostics,
                                 DIAGNOSTICS_QOS)
        self.rejections = Rejections(self)
        self.gate = JointStateGate(self.joint_names, self.rejections)
        self.health = Health(self, NAME)
        self.health.checks += [self._run_check,
                               rejections_check(self.rejections, "/joint_states")]
        self.create_timer(0.1, self.on_timer, clock=wall_clock())
        self.create_timer(1.0, self.on_health_timer, clock=wall_clock())
        self.get_logger().info(f"{config['law']} law, up to {config['max_trials']} trials; "
                               "waiting for the plant and the controller")

    @property
    def trial(self) -> int:
        """The trial running or next (1 before the session exists)."""
        return 1 if self.session is None else self.session.trial

    # --- protocol steps -------------------------------------------------------------------
    def _enter(self, phase: Phase) -> None:
        self.phase = phase
        self.phase_since = time.monotonic()

    def on_timer(self) -> None:
        """Start once the graph is up; retry a refused start; discard a stuck trial."""
        if self.phase is Phase.WAIT_GRAPH:
            if self.reset_client.service_is_ready() and self.start_client.service_is_ready() \
                    and self.state_sub.get_publisher_count() >= 1 and \
                    (self.recorder_ready or not self.params.config["wait_for_recorder"]):
                if self.session is None:
                    self._prepare()
                elif not self.session.finished:
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
                                    f"{STEP_TIMEOUT:g} s; discarding the trial and running it "
                                    "again with the same feed-forward")
            self._retry("timeout", [("phase", self.phase.value)])
        elif self.phase is Phase.STARTING and self.start_future is None:
            self._start()

    def _reset(self) -> None:
        self._enter(Phase.RESETTING)
        self.samples.stop()
        self.reset_client.call_async(Trigger.Request()).add_done_callback(self.on_reset_done)

    def on_reset_done(self, future: Future) -> None:
        """Plant at x_d(0): push this trial's feed-forward stamped with its t0."""
        response = future.result()
        if self.phase is not Phase.RESETTING or response is None:
            return
        if not response.success or not response.message.startswith(topics.T0_PREFIX):
            self.get_logger().error(f"plant reset failed: {response.message}")
            return
        self.samples.start(int(response.message[len(topics.T0_PREFIX):]))
        self.done_report = None
        self.gate.restart()
        self._enter(Phase.WAIT_ACK)
        assert self.session is not None
        self.feedforward_pub.publish(feedforward_message(
            self.reference, self.session.feedforward, self.trial, self.samples.t0_ns,
            self.samples.step_ns, self.joint_names))

    def poll(self) -> None:
        """Every /joint_states message waiting in the inbox (called by the spin loop)."""
        for _, _, raw in self.inbox.take():
            self.on_joint_state(raw)

    def destroy_node(self) -> None:
        """The inbox's companion node, then this one."""
        self.inbox.destroy()
        super().destroy_node()

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        """bag_recorder's filed trials; the controller's acknowledgement of this trial's
        feed-forward starts the trial; its ``done`` ends it once every sample is in."""
        self.poll()
        expected = {"trial": str(self.trial), "t0_ns": str(self.samples.t0_ns)}
        for item in msg.status:
            values = values_of(item)
            if item.name == topics.RECORDER_STATUS and item.message == "ready":
                self.recorder_ready = True
                filed = values.get("trials_filed", "0")
                self.recorder_filed = max(self.recorder_filed,
                                          int(filed) if filed.isdigit() else 0)
            elif {k: values.get(k) for k in expected} != expected:
                continue
            elif self.phase is Phase.RUNNING and item.message == "done" and \
                    item.name == topics.CONTROLLER_TRIAL_STATUS:
                self.done_report = values
                self._maybe_end_trial()
            elif self.phase is Phase.WAIT_ACK and item.name == topics.FEEDFORWARD_ACK_STATUS:
                if self.unsaved is not None:  # the previous trial is not in the bag yet
                    self.after_save = "start"
                    self._enter(Phase.WAIT_RECORDER)
                else:
                    self._begin_trial()
        if self.unsaved is not None and self.recorder_filed >= self.unsaved.record.trial:
            self._store_unsaved()

    def _begin_trial(self) -> None:
        self._event("start", [("trial", str(self.trial))], self.samples.t0_ns)
        self._enter(Phase.STARTING)
        self._start()

    def _start(self) -> None:
        self.start_future = self.start_client.call_async(Trigger.Request())
        self.start_future.add_done_callback(self.on_start_done)

    def on_start_done(self, future: Future) -> None:
        """Running, or refused (not linked yet): retried by the timer."""
        self.start_future = None
        response = future.result()
        if self.phase is not Phase.STARTING or response is None:
            return
        if response.success:
            self._enter(Phase.RUNNING)
        else:
            self.get_logger().info(f"plant refused start: {response.message}; retrying",
                                   throttle_duration_sec=2.0)

    def on_joint_state(self, raw: bytes) -> None:
        """Keep the samples of the current trial; the last one (with the controller's
        ``done``) ends it. Every message is checked (bad input is counted even between
        trials); only the current trial's samples are kept."""
        sample = self.gate(raw)
        if sample is None or not self.samples.add(*sample):
            return
        self.phase_since = time.monotonic()  # progress: a slow real-time trial is not stuck
        if self.samples.last_in:
            if self.samples.missing:
                missing = self.samples.missing
                self.get_logger().error(f"trial {self.trial}: {missing} samples lost; "
                                        "running the trial again")
                self._retry("lost", [("lost", str(missing))])
                return
            self._maybe_end_trial()

    def _maybe_end_trial(self) -> None:
        report = self.done_report
        if not self.samples.running or report is None or not self.samples.last_in:
            return
        trips = int(report.get("watchdog_trips", "0"))
        if trips:
            self.get_logger().error(f"trial {self.trial}: the controller's watchdog tripped "
                                    f"{trips}x (safe hold); running the trial again")
            self._retry("watchdog", [("watchdog_trips", str(trips))])
            return
        self._end_trial()

    def _retry(self, reason: str, values: Sequence[tuple[str, str]]) -> None:
        assert self.session is not None
        self.session.discard(reason)
        self._event("aborted", [("trial", str(self.trial)), ("reason", reason), *values])
        self._reset()

    def _end_trial(self) -> None:
        """Conclude the trial in the session; store it (once the recorder filed it) and go on
        with the next one, or finish."""
        assert self.session is not None and self.experiment is not None
        assert self.done_report is not None
        session = self.session
        aborted = int(self.done_report.get("aborted_at", "-1"))
        self.t0_ns_end = self.samples.end_ns
        self.samples.stop()
        record = record_from_samples(self.experiment, session.trial, session.feedforward,
                                     self.samples.position, self.samples.velocity,
                                     session.levels, self.reference,
                                     aborted if aborted >= 0 else None)
        self._stage_live_changes()
        try:
            conclusion = session.conclude(record)
        except ExoIlcError as exc:
            self._fail(str(exc))
            return
        if conclusion.applied:
            self.get_logger().info(f"parameters changed; applied from trial {session.trial}: "
                                   f"{json.dumps(conclusion.applied)}")
        for note in conclusion.update.notes if conclusion.learned else ():
            self.get_logger().info(f"learning from trial {record.trial}: {note}")
        if record.aborted:
            self.get_logger().error(f"trial {record.trial} aborted by the error envelope at "
                                    f"sample {aborted}; not learned from")
        summary = trial_summary(conclusion, self.joint_names)
        if record.aborted:
            self._event("aborted", [("trial", str(record.trial)), ("reason", "error_envelope"),
                                    ("aborted_at", str(aborted))], self.t0_ns_end)
        self.summary_pub.publish(diagnostic_array(self, [summary], self.t0_ns_end))
        self._event("end", [(kv.key, kv.value) for kv in summary.values], self.t0_ns_end)
        self.unsaved, self.unsaved_since = conclusion, time.monotonic()
        if self._recorder_pending(record.trial):
            # Stored only once the bag holds it too; the next trial is prepared meanwhile
            # (plant reset, feed-forward pushed) and starts after the store.
            if session.finished:
                self.after_save = "finish"
                self._enter(Phase.WAIT_RECORDER)
            else:
                self._reset()
        elif self._save_trial():
            if session.finished:
                self._finish(session.completed)
            else:
                self._reset()

    def _recorder_pending(self, trial: int) -> bool:
        return bool(self.params.config["wait_for_recorder"]) and not self.recorder_lost \
            and self.recorder_filed < trial

    def _stage_live_changes(self) -> None:
        """Accepted live parameter changes since the last boundary, into the session."""
        pending = self.params.pending
        if pending is self.seen or self.session is None:
            return
        changed = {name: pending[name] for name in sorted(LIVE)
                   if pending[name] != self.seen[name]}
        self.seen = pending
        self.session.stage(changed)

    def _save_trial(self) -> bool:
        """The concluded trial into the store (False: it could not be saved; the run
        stopped). With ``wait_for_recorder`` this runs only after bag_recorder filed the
        trial, so a stored trial is always in a bag: if the recorder dies first, the trial is
        not stored and a resume runs it again."""
        assert self.unsaved is not None
        conclusion, self.unsaved = self.unsaved, None
        if self.store is not None:
            try:
                self.store.save(conclusion.record, conclusion.update, conclusion.config)
            except (ExoIlcError, OSError) as exc:
                trial = conclusion.record.trial
                self._fail(f"trial {trial}: cannot save to the store: {exc}", trial - 1)
                return False
        return True

    def _store_unsaved(self) -> None:
        """The recorder filed the waiting trial (or went silent): store it, then start the
        next trial or finish if that was waiting for it."""
        if not self._save_trial() or self.phase is not Phase.WAIT_RECORDER:
            return
        assert self.session is not None
        if self.after_save == "finish":
            self._finish(self.session.completed)
        else:
            self._begin_trial()

    # --- start-up: the plant's parameters, the session, the store ----------------------------
    def _prepare(self) -> None:
        """Before trial 1: the plant's parameters (they label every summary and key the
        store), then the session (resumed from the store if asked)."""
        if self.plant_future is None:
            if self.plant_params.services_are_ready():
                self.plant_future = self.plant_params.get_parameters(PLANT_PARAMETERS)
            return
        if not self.plant_future.done():
            return
        result = self.plant_future.result()
        self.plant_future = None
        if result is None or len(result.values) != len(PLANT_PARAMETERS):
            return  # asked again at the next tick
        plant = {n: parameter_value_to_python(v)
                 for n, v in zip(PLANT_PARAMETERS, result.values, strict=True)}
        try:
            self._open_session(self.params.config.replace(plant))
        except ExoIlcError as exc:
            self._fail(str(exc), 0, code=2)

    def _open_session(self, config: Config) -> None:
        session = LearningSession(config)
        self.experiment = Experiment(config)
        if config["store.directory"]:
            self.store, _ = session.open_store(config["store.directory"],
                                               config["store.resume"])
            if session.completed:
                self.get_logger().info(f"resumed from {self.store.directory}: trials 1.."
                                       f"{session.completed} restored, continuing with trial "
                                       f"{session.trial}")
                self._event("resumed", [("trials", str(session.completed))])
        self.session = session
        if session.finished:
            self._finish(session.completed)

    def _finish(self, trials: int, values: Sequence[tuple[str, str]] = ()) -> None:
        self._enter(Phase.FINISHED)
        self._event("finished", [("trials", str(trials)), *values], self.t0_ns_end or None)
        self.get_logger().info(f"finished after {trials} trials")

    def _fail(self, message: str, completed: int | None = None, code: int = 1) -> None:
        """Stop running trials: ERROR on /diagnostics, ``finished`` with the error after
        ``completed`` trials (default: those the session concluded)."""
        self.error = message
        self.get_logger().error(message)
        if completed is None:
            completed = 0 if self.session is None else self.session.completed
        self._finish(completed, [("error", message)])
        self.on_health_timer()
        self.exit_code = code

    # --- health and messages -----------------------------------------------------------------
    def on_health_timer(self) -> None:
        """Health on /diagnostics."""
        self.health_pub.publish(diagnostic_array(self, [self.health.status()]))

    def _run_check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        aborted = [] if self.session is None else self.session.aborted_trials
        retried = [] if self.session is None else self.session.retried
        values = [("trial", str(self.trial)), ("phase", self.phase.value),
                  ("aborted_trials", " ".join(map(str, aborted))),
                  ("retried", " ".join(f"{k}:{why}" for k, why in retried)),
                  ("store", "" if self.store is None else str(self.store.directory)),
                  ("stored_trials", "0" if self.store is None else str(self.store.completed))]
        if self.error:
            return DiagnosticStatus.ERROR, self.error, values
        reasons = []
        if aborted:
            reasons.append(f"trials aborted by the error envelope: {aborted}")
        if retried:
            reasons.append(f"{len(retried)} trials run again")
        level = DiagnosticStatus.WARN if reasons else DiagnosticStatus.OK
        return level, "; ".join(reasons), values

    def _event(self, message: str, values: Sequence[tuple[str, str]],
               stamp: int | None = None) -> None:
        event = status(topics.TRIAL_STATUS, message, values, hardware_id=NAME)
        self.events_pub.publish(diagnostic_array(self, [event], stamp))


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros ilc_supervisor``."""
    return spin(IlcSupervisor, args)


if __name__ == "__main__":
    raise SystemExit(main())
