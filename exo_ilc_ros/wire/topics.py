"""Topic and service names of the graph, their types, and what each message carries.

One place for the wire contract shared by the nodes, the bag recorder and the offline analysis.
Every array is in the joint order of the ``joint_names`` parameter; times are simulated time.

``/joint_states`` (``sensor_msgs/msg/JointState``, plant_simulator)
    header.stamp = simulated time of the sample; name = joint_names; position, velocity = the
    measured state; effort = the effort applied over the period that *ended* at this sample
    (after the plant's own limit). One message per control period.
``/clock`` (``rosgraph_msgs/msg/Clock``, plant_simulator)
    Simulated time; monotonic over the whole run (it does not restart with each trial).
    Published at every ``clock_every``-th sample of a trial (plant parameter, default 10) and at
    each trial's first and last sample; the samples' own stamps are exact.
``/ground_truth/joint_states`` (``sensor_msgs/msg/JointState``, plant_simulator)
    Only when the virtual patient's sensors (``patient.sensor.*``) make the measured state
    differ from the true one: the same samples as /joint_states with the plant's true position
    and velocity (a simulator-only topic, as Gazebo offers ground truth); the supervisor reports
    the true max |e| from it. Not recorded in bags.
``/effort_controller/commands`` (``std_msgs/msg/Float64MultiArray``, computed_torque_controller)
    data = effort per joint (N m), the ros2_control JointGroupEffortController convention.
``/ilc/feedforward`` (``trajectory_msgs/msg/JointTrajectory``, ilc_supervisor; transient local)
    The profile of the next trial: header.frame_id = ``trial:<k>``; joint_names; one point per
    sample t_i with time_from_start = t_i, positions = q_d(t_i), velocities = qdot_d(t_i),
    accelerations = u_ff(t_i) (the learned feed-forward, rad/s^2), effort empty.
``/ilc/trial_events`` (``diagnostic_msgs/msg/DiagnosticArray``, ilc_supervisor)
    header.stamp = simulated time of the event; one status named ``ilc_supervisor/trial`` with
    message ``start``, ``end`` or ``aborted`` and values ``trial`` = k (and on ``end`` the same
    key-values as the summary).
``/ilc/trial_summary`` (``diagnostic_msgs/msg/DiagnosticArray``, ilc_supervisor)
    After each trial: one status named ``ilc_supervisor/trial_summary``, level OK if every joint
    is within the bound else WARN, values: ``trial``, ``mass_uncertainty``, ``law``,
    ``max_abs_error/<joint>``, ``max_abs_feedforward/<joint>``, ``max_abs_effort/<joint>``,
    ``level/M/<joint>``, ``level/M'/<joint>``, ``level/M''/<joint>`` (repr of floats, so
    they parse back exactly; every trial of a run has the same keys: ``nan`` where a trial
    has no level, as trial 1, which no update formed).
``/ilc/trial_metrics`` (``std_msgs/msg/Float64MultiArray``, ilc_supervisor; transient local)
    With each summary, the same trial's numbers as numbers (for a Plot panel): trial, level,
    then ``max |e|``, RMS e, ``max |u_ff|``, ``max |effort|``, M, M', M'' per joint, named by
    the layout (:mod:`.trial_metrics`).
``/diagnostics`` (``diagnostic_msgs/msg/DiagnosticArray``, every node): health.
    computed_torque_controller also acknowledges each feed-forward it loaded here: status
    ``computed_torque_controller/feedforward``, message ``loaded``, values ``trial`` = k and
    ``t0_ns``; its health status ``computed_torque_controller/health`` carries ``steps`` and the
    receive-to-publish latency percentiles ``latency_p50_us``, ``latency_p99_us`` of the last
    second. Every node publishes ``<node>/health`` once a second: level OK / WARN / ERROR,
    message = the reasons (inputs rejected per cause, effort saturation, watchdog trips,
    trials aborted by the error envelope, store failures), values = the counts.

QoS: /joint_states and /effort_controller/commands reliable, volatile, depth 1000;
/ilc/feedforward reliable, transient local, depth 1; /ilc/trial_events and /ilc/trial_summary
reliable, transient local, depth 1000 (late joiners get the history); /diagnostics reliable,
transient local, depth 10; /clock reliable, volatile, depth 1000 (depth 1 lost messages to a
loaded recorder: a reliable writer repairs a loss only from its history);
/ilc/trial_metrics as the summary. A volatile subscriber matches them all.
(Those are the writers'. The nodes read the loop's inputs keeping all, the feed-forward 100
deep and /diagnostics 1000 deep, and act only on messages from the contract's publisher:
:mod:`.publishers`.)

Trial protocol (the supervisor drives it; lock-step and real-time alike):

``/plant_simulator/reset`` (``std_srvs/srv/Trigger``)
    Puts the arm at x_d(0) and stops stepping; ``message`` is ``t0_ns=<int>``, the simulated
    time (ns) of the next trial's first sample. Sample i of the trial is stamped
    ``t0_ns + i * period_ns`` exactly (integer ns), so every node recovers i from the stamp.

``/ilc/feedforward`` for that trial then carries header.stamp = t0 (the trial's first sample).

``/plant_simulator/start`` (``std_srvs/srv/Trigger``)
    Publishes sample 0 and steps until sample N (the command at t_N is never applied). Fails
    (success false, with the reason) until the plant is linked to a controller, and, with a
    virtual patient, until it has the trial's /ilc/feedforward (stamp t0): its frame
    ``trial:<k>`` says which trial's random draws the patient uses.

``/ilc/trial_events`` message ``finished`` (values ``trials``) when the supervisor stops
(``max_trials`` reached or ``stop_when_settled``).
"""

from __future__ import annotations

JOINT_STATES = "/joint_states"
TRUE_JOINT_STATES = "/ground_truth/joint_states"
CLOCK = "/clock"
EFFORT_COMMANDS = "/effort_controller/commands"
FEEDFORWARD = "/ilc/feedforward"
TRIAL_EVENTS = "/ilc/trial_events"
TRIAL_SUMMARY = "/ilc/trial_summary"
TRIAL_METRICS = "/ilc/trial_metrics"
DIAGNOSTICS = "/diagnostics"
PARAMETER_EVENTS = "/parameter_events"

TYPES: dict[str, str] = {
    JOINT_STATES: "sensor_msgs/msg/JointState",
    CLOCK: "rosgraph_msgs/msg/Clock",
    EFFORT_COMMANDS: "std_msgs/msg/Float64MultiArray",
    FEEDFORWARD: "trajectory_msgs/msg/JointTrajectory",
    TRIAL_EVENTS: "diagnostic_msgs/msg/DiagnosticArray",
    TRIAL_SUMMARY: "diagnostic_msgs/msg/DiagnosticArray",
    TRIAL_METRICS: "std_msgs/msg/Float64MultiArray",
    DIAGNOSTICS: "diagnostic_msgs/msg/DiagnosticArray",
    PARAMETER_EVENTS: "rcl_interfaces/msg/ParameterEvent",
}
"""Every recorded topic of the graph and its ROS 2 type name (what the recorder subscribes to)."""

ROBOT_DESCRIPTION = "/robot_description"
REFERENCE_DESCRIPTION = "/reference/robot_description"
TF = "/tf"
VIEW_TYPES: dict[str, str] = {
    ROBOT_DESCRIPTION: "std_msgs/msg/String",
    REFERENCE_DESCRIPTION: "std_msgs/msg/String",
    TF: "tf2_msgs/msg/TFMessage",
}
"""The arm as the live view shows it (``bag/view.py``): its URDF and the reference arm's, as
robot_state_publisher publishes ``/robot_description``, and per sample the arm's and the
reference's joint transforms on ``/tf``. No node of the graph publishes them: the live view
and the bag writers compute them from the recorded samples and feed-forward."""

LIVE_TOPICS = (JOINT_STATES, EFFORT_COMMANDS, FEEDFORWARD, CLOCK, TRIAL_EVENTS, TRIAL_SUMMARY,
               TRIAL_METRICS, DIAGNOSTICS)
"""The graph's topics the live view forwards as they are (besides :data:`VIEW_TYPES`)."""
PER_SAMPLE = frozenset({JOINT_STATES, EFFORT_COMMANDS, CLOCK})
"""The control loop's per-sample topics (a view that falls behind may lose these, only)."""

BAG_TYPES: dict[str, str] = {**TYPES, **VIEW_TYPES}
"""Every topic a bag lists (the graph's recorder and ``exo-ilc simulate --bag`` alike)."""

RESET_SERVICE = "/plant_simulator/reset"
START_SERVICE = "/plant_simulator/start"

TRIAL_STATUS = "ilc_supervisor/trial"
SUMMARY_STATUS = "ilc_supervisor/trial_summary"
LEARNING_NOTES = "learning_notes"
"""Trial summary key: what the learning law said about its update from this trial, "; "-joined
(``norm_optimal.constrained``: the constraints active in the QP); absent when it said nothing."""
LEVEL_SYMBOLS = ("M", "M'", "M''")
"""The step gains in the summary keys ``level/<symbol>/<joint>``, in eq (11)'s order."""
FEEDFORWARD_FRAME_PREFIX = "trial:"
FEEDFORWARD_ACK_STATUS = "computed_torque_controller/feedforward"
RECORDER_STATUS = "bag_recorder/status"
"""bag_recorder's status on /diagnostics (every 0.2 s, and at once when a trial is filed):
message ``ready`` once it is subscribed to a publisher of every topic it records, else
``waiting``; values ``bag``, ``messages``, ``trials_received`` (the last trial whose end event
is recorded) and ``trials_filed`` (the last trial whose end event and summary are written and
whose storage file is finished: a kill -9 from then on loses nothing of it)."""
CONTROLLER_HEALTH_STATUS = "computed_torque_controller/health"
CONTROLLER_TRIAL_STATUS = "computed_torque_controller/trial"
"""Sent by the controller on /diagnostics after the last sample of each trial: message
``done``, values ``trial``, ``t0_ns``, ``aborted_at`` (first sample outside the error envelope,
-1: none) and ``watchdog_trips`` (in this trial). The supervisor ends a trial only with it: the
record is rebuilt with the safe hold from ``aborted_at``; a trial with a watchdog trip is run
again (the commands it got are not the ones the record would assume). Under ``protocol: homing``
(no reset/start services; the feed-forward's header stamp is a token naming the attempt) also
``homed`` (values ``trial``, ``token``, ``t0_ns`` = the stamp of the trial's sample 0) and
``homing_failed`` (``trial``, ``token``, ``t0_ns`` = -1, ``reason``); the trial summary then
adds ``samples_missing``, ``samples_late``, ``homing_time``, ``initial_error/<joint>`` and
``initial_velocity/<joint>`` (core/protocol/homing_protocol.py)."""
PLANT_HEALTH_STATUS = "plant_simulator/health"
PLANT_TRIAL_STATUS = "plant_simulator/trial"
"""Sent by the real-time plant on /diagnostics after each trial's last sample: message
``done``, values ``t0_ns``, ``periods`` (stepped), ``late_commands`` (periods run with the
previous command held because this period's had not arrived) and ``first_late`` (the first
such period, 1-based; -1: none). The supervisor ends a real-time
trial only with it, and runs it again when too many were late (``max_late_commands``)."""
SUPERVISOR_HEALTH_STATUS = "ilc_supervisor/health"
T0_PREFIX = "t0_ns="
ENVELOPE_REASON = "error_envelope"
"""``reason`` of the ``aborted`` event of a trial the error envelope aborted (kept, not learned
from); other reasons (``watchdog``, ``lost``, ``timeout``) mean the trial was run again."""
