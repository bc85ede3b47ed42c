"""Topic and service names of the graph and their message types: the wire contract shared by the
nodes, the bag recorder and the offline analysis. What each message carries, its publisher, QoS
and the trial protocol: docs/wire-contract.md."""

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

CUFF_WRENCHES = ("/cuffs/upper_arm/wrench", "/cuffs/forearm/wrench")
"""A person strapped in the exoskeleton (``musculoskeletal.model``, core/person/): per sample
and cuff (upper arm, forearm: the order of ``core.person.cuffs.CUFFS``) the force (N) and
torque (N m) the cuff applies to the person, in the cuff's frame (x mediolateral, y
anteroposterior, z along the limb; ``header.frame_id`` :data:`CUFF_FRAMES`), stamped as the
sample's /joint_states, published by the plant just before it. What a force-torque sensor in a
cuff publishes. Only with a person: a run without one has no such topic (not in :data:`TYPES`;
a bag lists them only when it holds a person's run)."""
CUFF_FRAMES = ("upper_arm_cuff", "forearm_cuff")
CUFF_TYPE = "geometry_msgs/msg/WrenchStamped"
CUFF_TYPES: dict[str, str] = {topic: CUFF_TYPE for topic in CUFF_WRENCHES}

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
PERSON_JOINT_STATES = "/person/joint_states"
"""A person strapped in: per sample the person's own joints (``sensor_msgs/JointState``, the
MuJoCo joints of the person in qpos order: position rad, velocity rad/s, effort NaN: not
given), stamped as the sample's /joint_states and published by the plant just before it. What
drawing the person needs (with :data:`PERSON_DESCRIPTION`); the exoskeleton's joints are not
the person's (soft cuffs, misaligned axes)."""
PERSON_DESCRIPTION = "/person/robot_description"
"""A person strapped in: the person's display URDF (``std_msgs/String``,
``core/person/display.py``), published once by the plant, transient local (as
robot_state_publisher publishes ``/robot_description``): frames ``person/<body>`` hung from the
exoskeleton's root link, joints named as in :data:`PERSON_JOINT_STATES`."""
PERSON_LIVE_TOPICS = (*CUFF_WRENCHES, PERSON_JOINT_STATES, PERSON_DESCRIPTION)
"""With a person strapped in (``musculoskeletal.model``), the live view forwards these too, as
they are (their types: :data:`PERSON_TYPES`)."""
PERSON_TYPES: dict[str, str] = {**CUFF_TYPES,
                                PERSON_JOINT_STATES: "sensor_msgs/msg/JointState",
                                PERSON_DESCRIPTION: "std_msgs/msg/String"}
"""The topics a person's run adds to the graph's recorded ones, and their types."""
PER_SAMPLE = frozenset({JOINT_STATES, EFFORT_COMMANDS, CLOCK, *CUFF_WRENCHES,
                        PERSON_JOINT_STATES})
"""The control loop's per-sample topics (a view that falls behind may lose these, only; the
live view shows each at its display rate)."""

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
trial only with it, and runs it again when too many were late (``max_late_commands``).
Sent by every plant node whose state stopped being finite, instead of that sample: message
``diverged``, values ``stamp_ns`` (of the sample), ``t0_ns`` (-1: a plant without trials),
``joint``, ``joint_name``, ``time`` and ``cause``; the supervisor ends the trial there."""
SUPERVISOR_HEALTH_STATUS = "ilc_supervisor/health"
T0_PREFIX = "t0_ns="
ENVELOPE_REASON = "error_envelope"
"""``reason`` of the ``aborted`` event of a trial the error envelope aborted (kept, not learned
from); other reasons (``watchdog``, ``lost``, ``timeout``) mean the trial was run again."""
DIVERGED_REASON = "plant_diverged"
"""``reason`` of the ``aborted`` event of a trial whose plant diverged (kept, ``aborted_at`` the
first non-finite sample; ``core.loop.divergence.DIVERGED``): not run again, the run stops."""
CUFF_LIMIT_REASON = "cuff_force_limit"
"""``reason`` of the ``aborted`` event of a trial a cuff pressed past
``safety.cuff_force_limit`` in (kept, learned from up to ``aborted_at``, as an envelope abort;
the plant held the arm safe from that sample on)."""
KEPT_REASONS = (ENVELOPE_REASON, DIVERGED_REASON, CUFF_LIMIT_REASON)
"""``aborted`` events of trials that were kept (not run again)."""
