"""ilc_supervisor: the ROS binding of :class:`core.protocol.TrialProtocol`, which runs the trials
of a :class:`core.session.LearningSession` (all rules live there).

This node turns the plant's services (``reset``, ``start``), ``/joint_states`` (checked by
:class:`JointStateGate`), the controller's and the recorder's statuses on ``/diagnostics`` and
the live parameters into protocol calls, and the protocol's requests into messages: the
feed-forward (latched ``/ilc/feedforward``), ``/ilc/trial_summary`` and ``/ilc/trial_events``.
Before trial 1 it reads the plant's parameters (mass uncertainty, integration: they label the
summaries and key the store).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.serialization import deserialize_message
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from ..core.loop.divergence import DIVERGED
from ..core.loop.wire_input import Cause, Rejection
from ..core.params import schema
from ..core.programs.identified import Identified
from ..core.protocol.homing_protocol import HomingProtocol
from ..core.protocol.trial_protocol import TrialProtocol
from ..core.session.abort import ABORT_STOP_KEY
from ..core.session.learning_session import TrialConclusion
from ..wire import topics
from ..wire.protocol import int_value
from ..wire.publishers import max_bytes
from .common import (
    DIAGNOSTICS_QOS,
    EVENTS_QOS,
    LATCHED_QOS,
    CountingPublisher,
    Inbox,
    spin,
    wall_clock,
)
from .diagnostics import diagnostic_array, stamp_ns, status, values_of
from .guard import Health, JointStateGate, Rejections, rejections_check
from .messages import feedforward_message, trial_metrics_message, trial_summary
from .parameters import SchemaParameters
from .sender_check import STATUS_READER_QOS, Admission, StatusAdmission, gate_classifier

NAME = schema.SUPERVISOR
PLANT_PARAMETERS = [p.name for p in schema.PARAMETERS if p.section == schema.PLANT]
PLANT_PARAMETER_WAIT = 5.0
"""protocol homing: wall seconds to wait for a plant's parameter service before going on
without it (a real arm has none)."""


class IlcSupervisor(Node):
    """Trial orchestration: messages and services in, :class:`TrialProtocol` calls out."""

    def __init__(self) -> None:
        super().__init__(NAME)
        self.params = SchemaParameters(self, NAME)
        config = self.params.config
        self.joint_names: list[str] = config["joint_names"]
        self.homing = config["protocol"] == "homing"  # no reset/start: any arm
        self.protocol = (HomingProtocol if self.homing else TrialProtocol)(
            config, self, lambda: self.params.pending)
        self.plant_future: Future | None = None
        self.plant_wait_since = 0.0
        self.recorder_ready = False

        self.reset_client = self.create_client(Trigger, topics.RESET_SERVICE)
        self.start_client = self.create_client(Trigger, topics.START_SERVICE)
        self.plant_params = AsyncParameterClient(self, schema.PLANT)
        self.feedforward_pub = self.create_publisher(JointTrajectory, topics.FEEDFORWARD,
                                                     LATCHED_QOS, publisher_class=CountingPublisher)
        self.events_pub = self.create_publisher(DiagnosticArray, topics.TRIAL_EVENTS, EVENTS_QOS,
                                                publisher_class=CountingPublisher)
        self.summary_pub = self.create_publisher(DiagnosticArray, topics.TRIAL_SUMMARY,
                                                 EVENTS_QOS, publisher_class=CountingPublisher)
        self.metrics_pub = self.create_publisher(Float64MultiArray, topics.TRIAL_METRICS,
                                                 EVENTS_QOS, publisher_class=CountingPublisher)
        self.health_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS,
                                                DIAGNOSTICS_QOS, publisher_class=CountingPublisher)
        self.rejections = Rejections(self)
        self.gate = JointStateGate(self.joint_names, self.rejections)
        self.samples_from = self._state_admission(topics.JOINT_STATES)  # the plant's only
        self.inbox = Inbox(self)  # the trial's samples, drained in batches (see Inbox)
        self.state_sub = self.inbox.subscribe(JointState, topics.JOINT_STATES,
                                              admit=self.samples_from.admit_raw)
        self.inbox.subscribe(DiagnosticArray, topics.DIAGNOSTICS, STATUS_READER_QOS,
                             admit=StatusAdmission(self, self.rejections))  # own statuses only
        self.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self.on_status_bell,
                                 STATUS_READER_QOS, raw=True)  # wakes poll at once
        self.truth_from = self._state_admission(topics.TRUE_JOINT_STATES)
        self.inbox.subscribe(JointState, topics.TRUE_JOINT_STATES,  # the virtual patient's
                             admit=self.truth_from.admit_raw)
        self.truth_gate = JointStateGate(self.joint_names, self.rejections)
        self.cuffs_from = [Admission(self, topic, self.rejections,  # a person's cuffs: the
                                     max_bytes(topic, config.joints, 0))  # plant's only
                           for topic in topics.CUFF_WRENCHES]
        for topic, admission in zip(topics.CUFF_WRENCHES, self.cuffs_from, strict=True):
            self.inbox.subscribe(WrenchStamped, topic, admit=admission.admit_raw)
        self.health = Health(self, NAME)
        self.identified: Identified | None = None
        """The identified patient after the last trial (``identification.enabled``)."""
        self.health.checks += [self._run_check, self._identification_check,
                               rejections_check(self.rejections, "inputs"),
                               self.samples_from.health, self.truth_from.health]
        self.create_timer(0.1, self.on_timer, clock=wall_clock())
        self.create_timer(1.0, self.on_health_timer, clock=wall_clock())
        self.get_logger().info(f"{config['law']} law, up to {config['max_trials']} trials; "
                               "waiting for the plant and the controller")

    @property
    def exit_code(self) -> int | None:
        """Set when the node must stop (read by common.spin)."""
        return self.protocol.exit_code

    def _state_admission(self, topic: str) -> Admission:
        """JointStates on ``topic`` admitted only from ``joint_states_publisher``
        (wire.publishers); a foreign one is checked like the plant's to count its cause."""
        config = self.params.config
        return Admission(self, topic, self.rejections, max_bytes(topic, config.joints, 0),
                         gate_classifier(JointStateGate(self.joint_names, self.rejections)),
                         trusted=config["joint_states_publisher"])

    # --- inputs -----------------------------------------------------------------------------
    def on_timer(self) -> None:
        """Read the plant's parameters once the graph is up, then drive the protocol."""
        ready = (self.homing or (self.reset_client.service_is_ready() and
                 self.start_client.service_is_ready())) \
            and self.state_sub.get_publisher_count() >= 1 and \
            self.samples_from.trusted_known() and \
            (self.recorder_ready or not self.params.config["wait_for_recorder"])
        if ready and self.protocol.session is None and self.protocol.error is None:
            self._read_plant_parameters()
        self.protocol.tick(ready)

    def _read_plant_parameters(self) -> None:
        if self.plant_future is None:
            if self.plant_params.services_are_ready():
                self.plant_future = self.plant_params.get_parameters(PLANT_PARAMETERS)
            elif self.homing:  # a real arm has no plant_simulator parameters
                now = time.monotonic()
                self.plant_wait_since = self.plant_wait_since or now
                if now - self.plant_wait_since > PLANT_PARAMETER_WAIT:
                    self.get_logger().warning(
                        f"no {schema.PLANT} parameters after {PLANT_PARAMETER_WAIT:g} s (an arm "
                        "of your own): summaries and the store use this node's "
                        f"mass_uncertainty {self.params.config['mass_uncertainty']:g}")
                    self.protocol.open({})
            return
        if not self.plant_future.done():
            return
        result, self.plant_future = self.plant_future.result(), None
        if result is not None and len(result.values) == len(PLANT_PARAMETERS):
            self.protocol.open({n: parameter_value_to_python(v)
                                for n, v in zip(PLANT_PARAMETERS, result.values, strict=True)})

    def on_reset_done(self, future: Future) -> None:
        """The plant's answer: ``t0_ns=<stamp of the trial's first sample>``."""
        response = future.result()
        if response is None:
            return
        ok = response.success and response.message.startswith(topics.T0_PREFIX)
        t0 = int(response.message[len(topics.T0_PREFIX):]) if ok else None
        self.protocol.on_reset(t0, response.message)
        samples = self.protocol.samples
        if t0 is not None and samples.t0_ns == t0:  # taken: the trial's own stamps only
            self.gate.restart((t0, samples.end_ns))
            self.truth_gate.restart((t0, samples.end_ns))

    def on_start_done(self, future: Future) -> None:
        """Running, or refused (not linked yet: retried)."""
        response = future.result()
        if response is not None:
            self.protocol.on_started(response.success, response.message)

    def poll(self) -> None:
        """Every /joint_states and admitted /diagnostics message waiting in the inbox, in the
        order they arrived (called by the spin loop and for every /diagnostics message): every
        sample is checked (bad input is counted even between trials), and every sample of a
        trial is in before its ``done`` is looked at."""
        for _, topic, raw in self.inbox.take():
            if topic == topics.DIAGNOSTICS:
                self.on_diagnostics(deserialize_message(raw, DiagnosticArray))
                continue
            if topic == topics.TRUE_JOINT_STATES:
                true = self.truth_gate(raw)
                if true is not None:
                    self.protocol.on_true_sample(*true)
                continue
            if topic in topics.CUFF_WRENCHES:
                self._on_cuff_wrench(topics.CUFF_WRENCHES.index(topic), raw)
                continue
            sample = self.gate(raw)
            if sample is not None:
                self.protocol.on_sample(*sample)

    def _on_cuff_wrench(self, cuff: int, raw: bytes) -> None:
        """One cuff's wrench at one sample (a person strapped in), to the protocol."""
        try:
            msg = deserialize_message(raw, WrenchStamped)
        except Exception:  # the plant's own message: a bad one is counted, never acted on
            self.rejections.reject(Rejection(Cause.NOT_NUMERIC, f"{topics.CUFF_WRENCHES[cuff]}: "
                                             "undecodable"))
            return
        f, t = msg.wrench.force, msg.wrench.torque
        self.protocol.on_cuff_sample(cuff, stamp_ns(msg.header.stamp),
                                     np.array([f.x, f.y, f.z, t.x, t.y, t.z]))

    def on_status_bell(self, raw: bytes) -> None:
        """A /diagnostics message arrived: take it (with its sender) through the inbox now."""
        self.poll()

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        """The recorder's filed trials, the controller's acknowledgement and ``done``."""
        for item in msg.status:
            values = values_of(item)
            if item.name == topics.RECORDER_STATUS and item.message == "ready":
                self.recorder_ready = True
                self.protocol.on_recorder_filed(int_value(values, "trials_filed") or 0)
                continue
            if item.name == topics.PLANT_TRIAL_STATUS and item.message == "done":
                self.protocol.on_plant_done(int_value(values, "t0_ns") or -1, values)
                continue
            if item.name == topics.PLANT_TRIAL_STATUS and item.message == "diverged":
                self.protocol.on_plant_diverged(values)
                continue
            trial, t0 = int_value(values, "trial"), int_value(values, "t0_ns")
            if trial is None or t0 is None:
                continue
            if item.name == topics.FEEDFORWARD_ACK_STATUS:
                self.protocol.on_acknowledged(trial, t0)
            elif item.name == topics.CONTROLLER_TRIAL_STATUS and item.message == "done":
                self.protocol.on_done(trial, t0, values)
            elif item.name == topics.CONTROLLER_TRIAL_STATUS and \
                    isinstance(self.protocol, HomingProtocol):
                self._on_homing_report(item.message, trial, t0, values)

    def _on_homing_report(self, message: str, trial: int, t0: int,
                          values: dict[str, str]) -> None:
        """The controller's ``homed`` (t0 of the trial) or ``homing_failed`` (reason)."""
        assert isinstance(self.protocol, HomingProtocol)
        token = int_value(values, "token")
        if token is None:
            return
        if message == "homed":
            self.protocol.on_homed(trial, token, t0, int_value(values, "homing_start_ns") or 0)
        elif message == "homing_failed":
            self.protocol.on_homing_failed(trial, token, values.get("reason", ""))

    def destroy_node(self) -> None:
        """The inbox's companion node, then this one."""
        self.inbox.destroy()
        super().destroy_node()

    # --- the protocol's requests (core.protocol.GraphPort) ----------------------------------
    def reset(self) -> None:
        """Ask the plant to go to x_d(0)."""
        self.reset_client.call_async(Trigger.Request()).add_done_callback(self.on_reset_done)

    def start(self) -> None:
        """Ask the plant to start stepping."""
        self.start_client.call_async(Trigger.Request()).add_done_callback(self.on_start_done)

    def push_feedforward(self, trial: int, t0_ns: int, feedforward: np.ndarray,
                         joint_force: np.ndarray | None = None) -> None:
        """The trial's profile (and joint forces) on the latched /ilc/feedforward."""
        self.feedforward_pub.publish(feedforward_message(
            self.protocol.reference, feedforward, trial, t0_ns, self.protocol.samples.step_ns,
            self.joint_names, joint_force))

    def publish_conclusion(self, conclusion: TrialConclusion, end_ns: int) -> None:
        """Summary and ``end`` event (``aborted`` first for an envelope abort)."""
        record = conclusion.record
        if record.aborted:
            diverged = self.protocol.divergence is not None and \
                self.protocol.divergence.sample == record.aborted_at
            pressed = self.protocol.cuff_abort == record.aborted_at
            self.event("aborted", [("trial", str(record.trial)),
                                   ("reason", topics.DIVERGED_REASON if diverged
                                    else topics.CUFF_LIMIT_REASON if pressed
                                    else topics.ENVELOPE_REASON),
                                   ("aborted_at", str(record.aborted_at))], end_ns)
        summary = trial_summary(conclusion, self.joint_names)
        if conclusion.joint_forces is not None:  # on /diagnostics too (the health)
            self.identified = Identified.from_step(conclusion.joint_forces, self.joint_names)
        if isinstance(self.protocol, HomingProtocol):
            summary.values.extend(KeyValue(key=k, value=v) for k, v in
                                  self.protocol.summary_values(record, self.joint_names))
        if self.protocol.plant_report is not None:  # real time: the plant's late commands
            summary.values += status("", "", [
                (k, self.protocol.plant_report.get(k, "")) for k in (
                    "late_commands", "periods", "first_late")]).values
        if self.protocol.divergence is not None:  # the plant diverged: when, where, why
            summary.values.append(KeyValue(key=DIVERGED, value=json.dumps(
                self.protocol.divergence.to_json())))
        if conclusion.stop_message:  # the one message of a run stopped by aborts
            summary.values.append(KeyValue(key=ABORT_STOP_KEY, value=conclusion.stop_message))
        self.summary_pub.publish(diagnostic_array(self, [summary], end_ns))
        self.metrics_pub.publish(trial_metrics_message(summary, self.joint_names))
        self.event("end", [(kv.key, kv.value) for kv in summary.values], end_ns)

    def event(self, message: str, values: Sequence[tuple[str, str]],
              stamp_ns: int | None = None) -> None:
        """A trial event; at ``finished`` the health goes out at once (an error included)."""
        item = status(topics.TRIAL_STATUS, message, values, hardware_id=NAME)
        self.events_pub.publish(diagnostic_array(self, [item], stamp_ns))
        if message == "finished":
            self.on_health_timer()

    def log(self, error: bool, text: str) -> None:
        """The protocol's lines, in this node's log."""
        if error:
            self.get_logger().error(text)
        else:
            self.get_logger().info(text)

    # --- health -----------------------------------------------------------------------------
    def on_health_timer(self) -> None:
        """Health on /diagnostics."""
        self.health_pub.publish(diagnostic_array(self, [self.health.status()]))

    def _identification_check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        """The identified patient after the last trial (nothing before one, or when off)."""
        values = [] if self.identified is None else self.identified.status_values()
        return DiagnosticStatus.OK, "", values

    def _run_check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        protocol, session = self.protocol, self.protocol.session
        aborted = [] if session is None else session.aborted_trials
        retried = [] if session is None else session.retried
        store = protocol.store
        values = [("trial", str(protocol.trial)), ("phase", protocol.phase.value),
                  ("aborted_trials", " ".join(map(str, aborted))),
                  ("retried", " ".join(f"{k}:{why}" for k, why in retried)),
                  ("store", "" if store is None else str(store.directory)),
                  ("stored_trials", "0" if store is None else str(store.completed)),
                  ("feedforward_pushed_again", str(protocol.ack_retries))]
        if protocol.error:
            return DiagnosticStatus.ERROR, protocol.error, values
        reasons = []
        if aborted:
            reasons.append(f"trials aborted by the error envelope: {aborted}")
        if session is not None and session.stop_message:
            reasons.append(session.stop_message)
        if retried:
            reasons.append(f"{len(retried)} trials run again")
        level = DiagnosticStatus.WARN if reasons else DiagnosticStatus.OK
        return level, "; ".join(reasons), values


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros ilc_supervisor``."""
    return spin(IlcSupervisor, args)


if __name__ == "__main__":
    raise SystemExit(main())
