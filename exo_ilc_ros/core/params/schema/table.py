"""The parameter table: every parameter's name, ROS section, type and rule, in one list
(:data:`PARAMETERS`, :data:`BY_NAME`). New keys go here, in the section they belong to.
Longer than ~450 lines on purpose: one table of every parameter is the point (the one schema
YAML loading, ROS declaration, validation and the bags' provenance all read)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from .drive import drive_parameters
from .key_groups import MODEL_SOURCES, PATIENT_JOINTS, PERSON_SEGMENTS, URDF_JOINT_DYNAMICS
from .musculoskeletal import musculoskeletal_parameters
from .parameter import CONTROLLER, PLANT, SHARED, SUPERVISOR, Kind, Parameter
from .rules import (
    MAS_GRADES,
    _averaging_memory_rule,
    _axes_rule,
    _direction_rule,
    _forgetting_rule,
    _fraction_rule,
    _locks_problem,
    _margin_rule,
    _name_rule,
    _node_name_rule,
    _patient_joints_problem,
    _pole_rule,
    _priority_rule,
    _range_rule,
    _retention_rule,
    _share_rule,
    _vector_rule,
)


def _patient_parameters() -> list[Parameter]:
    """The virtual patient's effects (core/loop/patient.py), plant_simulator section, all off by
    default."""
    def p(name: str, kind: Kind, text: str, **rules: Any) -> Parameter:
        return Parameter(f"patient.{name}", PLANT, kind, text, **rules)

    joint = {"per_joint": True, "patient_joint": True, "minimum": 0.0}
    return [
        Parameter(PATIENT_JOINTS, SHARED, Kind.STRING, "the patient's joints and the arm joint "
                  "each acts on, 'patient_joint: arm_joint, ...' ('-arm_joint': the patient's "
                  "angle grows as the arm's falls); every patient.* per-joint list is in this "
                  "order, arm joints not named get no patient effect; empty: the patient's "
                  "joints are the arm's (joint_names)",
                  extra_rule=_patient_joints_problem),
        p("seed", Kind.INTEGER, "seed of the patient's random numbers (trial k draws from "
          "SeedSequence([seed, k]))", minimum=0.0),
        p("session", Kind.INTEGER, "the patient's therapy session the run is (1: the first, "
          "or no session): session s >= 2 draws trial k from SeedSequence([seed, s, k]); "
          "--patient sets it to the profile version the session writes", minimum=1.0),
        p("sensor.quantisation", Kind.DOUBLE, "encoder resolution (rad); 0: none",
          minimum=0.0),
        p("sensor.position_noise", Kind.DOUBLE, "Gaussian noise on the measured q, sd (rad)",
          minimum=0.0),
        p("sensor.velocity_noise", Kind.DOUBLE, "Gaussian noise on the measured qdot, sd "
          "(rad/s)", minimum=0.0),
        p("sensor.differentiate_velocity", Kind.BOOL, "measured qdot = difference of the "
          "measured (quantised) q over the period, as most exoskeletons do"),
        p("sensor.velocity_filter", Kind.DOUBLE, "first-order low-pass on the measured qdot, "
          "time constant (s); 0: none", minimum=0.0),
        p("friction.viscous", Kind.DOUBLE_ARRAY, "viscous joint friction B (N m s/rad)",
          **joint),
        p("friction.coulomb", Kind.DOUBLE_ARRAY, "Coulomb friction F_c of F_c tanh(qdot / v_s) "
          "(N m)", **joint),
        p("friction.stribeck_velocity", Kind.DOUBLE, "v_s of the tanh Coulomb model (rad/s)",
          strictly_positive=True),
        p("passive.stiffness", Kind.DOUBLE_ARRAY, "passive joint stiffness K of "
          "K (q - q_0) (N m/rad)", **joint),
        p("passive.rest_position", Kind.DOUBLE_ARRAY, "q_0: where the passive (and spastic) "
          "stiffness exerts no torque (rad, the patient's angle: from patient.joint_zero, "
          "signed as patient.joints)", per_joint=True, patient_joint=True),
        Parameter("patient.joint_zero", SHARED, Kind.DOUBLE_ARRAY, "the arm joint's angle "
                  "where the patient's joint is at 0 (rad; the patient's angles, "
                  "passive.rest_position, count from it)", per_joint=True, patient_joint=True),
        p("spasticity.mas_grade", Kind.STRING, "custom (the values below) or a Modified "
          "Ashworth grade 0, 1, 1+, 2, 3 (its preset replaces them)", choices=MAS_GRADES),
        p("spasticity.stiffness", Kind.DOUBLE_ARRAY, "spastic stiffness added to "
          "passive.stiffness (N m/rad)", **joint),
        p("spasticity.damping", Kind.DOUBLE_ARRAY, "velocity-dependent resistance added to "
          "the viscous friction (N m s/rad)", **joint),
        p("spasticity.reflex_gain", Kind.DOUBLE_ARRAY, "stretch reflex torque per rad/s of "
          "the delayed velocity above the threshold (N m s/rad)", **joint),
        p("spasticity.reflex_threshold", Kind.DOUBLE_ARRAY, "velocity threshold of the "
          "stretch reflex (rad/s)", **joint),
        p("spasticity.reflex_max", Kind.DOUBLE_ARRAY, "ceiling of the stretch reflex torque "
          "(N m; the reflex is clipped to +-reflex_max); 0: no ceiling", **joint),
        p("spasticity.reflex_delay", Kind.DOUBLE, "stretch reflex delay (s; rounded to "
          "control periods)", minimum=0.0),
        p("voluntary.stiffness", Kind.DOUBLE_ARRAY, "K_v: the patient's own torque toward the "
          "reference per rad of error (N m/rad); 0: a passive patient", **joint),
        p("voluntary.damping", Kind.DOUBLE_ARRAY, "D_v: the patient's torque per rad/s of "
          "velocity error (N m s/rad)", **joint),
        p("voluntary.time_constant", Kind.DOUBLE, "lag of the voluntary torque (s): sluggish "
          "tracking; 0: none", minimum=0.0),
        p("voluntary.amplitude_sd", Kind.DOUBLE, "trial-to-trial sd of the voluntary gain "
          "(share of it)", minimum=0.0),
        p("voluntary.timing_sd", Kind.DOUBLE, "trial-to-trial sd of the patient's timing "
          "(s; rounded to control periods)", minimum=0.0),
        p("voluntary.fatigue_rate", Kind.DOUBLE, "r of the fatigue f_k = f_min + (1 - f_min) "
          "exp(-r (k - 1)) on the voluntary gain (per trial)", minimum=0.0),
        p("voluntary.fatigue_floor", Kind.DOUBLE, "f_min: the share of the voluntary gain "
          "fatigue leaves", minimum=0.0, extra_rule=_fraction_rule),
        p("initial.position_sd", Kind.DOUBLE, "trial-to-trial sd of q(0) about q_d(0) (rad)",
          minimum=0.0),
        p("initial.velocity_sd", Kind.DOUBLE, "trial-to-trial sd of qdot(0) (rad/s)",
          minimum=0.0),
        p("learning.gain", Kind.DOUBLE_ARRAY, "K_e: torque the patient learns per rad of the "
          "true error of a trial (N m/rad; two-state model, core/loop/patient.py); 0: no learning",
          **joint),
        p("learning.fast_retention", Kind.DOUBLE, "A_f of the fast state x_f <- A_f x_f + "
          "B_f K_e e", minimum=0.0, extra_rule=_retention_rule),
        p("learning.fast_rate", Kind.DOUBLE, "B_f of the fast state", minimum=0.0),
        p("learning.slow_retention", Kind.DOUBLE, "A_s of the slow state x_s <- A_s x_s + "
          "B_s K_e e", minimum=0.0, extra_rule=_retention_rule),
        p("learning.slow_rate", Kind.DOUBLE, "B_s of the slow state", minimum=0.0),
        p("effort_delay", Kind.INTEGER, "control periods between a command and its torque at "
          "the joint", minimum=0.0),
    ]
def _person_parameters() -> list[Parameter]:
    """A person in the exoskeleton (core/arm/body_segments.py, de Leva 1996): off by default."""
    out = [
        Parameter("person.enabled", SHARED, Kind.BOOL,
                  "the plant carries a person's upper arm, forearm and hand (de Leva 1996 "
                  "segments from body mass and height) strapped to the links below; "
                  "model.source urdf only (the paper's cone links are the arm itself)"),
        Parameter("person.in_nominal", SHARED, Kind.BOOL,
                  "the nominal model (computed torque, the norm-optimal law's model) carries "
                  "the person too; false: the lab knows its robot, not the patient, and the "
                  "learning takes the person up"),
        Parameter("person.body_mass", SHARED, Kind.DOUBLE, "the person's body mass (kg)",
                  strictly_positive=True),
        Parameter("person.height", SHARED, Kind.DOUBLE, "the person's height (m): scales "
                  "de Leva's segment lengths", strictly_positive=True),
        Parameter("person.sex", SHARED, Kind.STRING, "de Leva's table: male or female",
                  choices=("male", "female")),
    ]
    for segment in PERSON_SEGMENTS:
        base = f"person.{segment}"
        out += [
            Parameter(f"{base}.link", SHARED, Kind.STRING,
                      f"the exoskeleton link the {segment} is strapped to (it moves with that "
                      "link's body); empty: left out"),
            Parameter(f"{base}.length", SHARED, Kind.DOUBLE,
                      f"the {segment}'s measured joint-to-joint length (m); 0: de Leva's "
                      "reference length scaled by person.height", minimum=0.0),
            Parameter(f"{base}.origin", SHARED, Kind.DOUBLE_ARRAY,
                      f"the {segment}'s proximal joint centre in the link's frame (m)",
                      extra_rule=_vector_rule),
            Parameter(f"{base}.direction", SHARED, Kind.DOUBLE_ARRAY,
                      f"the {segment}'s direction, proximal to distal, in the link's frame",
                      extra_rule=_direction_rule),
            Parameter(f"{base}.sagittal_axis", SHARED, Kind.DOUBLE_ARRAY,
                      f"the {segment}'s sagittal (anteroposterior) axis in the link's frame, "
                      "normal to its direction", extra_rule=_direction_rule),
        ]
    return out


def _schedule_parameters() -> list[Parameter]:
    out = []
    meaning = {"position": ("M", "|s e|"), "velocity": ("M'", "|s e_dot|"),
               "acceleration": ("M''", "|s e_ddot|")}
    for term, (symbol, total) in meaning.items():
        base = f"schedule.{term}"
        out += [
            Parameter(f"{base}.threshold_low", SUPERVISOR, Kind.DOUBLE_ARRAY,
                      f"s1 of {symbol}: {total} at or below it gives level_low, eqs (22)-(24)",
                      per_joint=True, minimum=0.0, live=True),
            Parameter(f"{base}.threshold_high", SUPERVISOR, Kind.DOUBLE_ARRAY,
                      f"s2 of {symbol}: {total} above it gives level_high", per_joint=True,
                      minimum=0.0, live=True),
            Parameter(f"{base}.level_low", SUPERVISOR, Kind.DOUBLE_ARRAY,
                      f"{symbol} step when {total} <= threshold_low", per_joint=True,
                      minimum=0.0, live=True),
            Parameter(f"{base}.level_mid", SUPERVISOR, Kind.DOUBLE_ARRAY,
                      f"{symbol} step when threshold_low < {total} <= threshold_high",
                      per_joint=True, minimum=0.0, live=True),
            Parameter(f"{base}.level_high", SUPERVISOR, Kind.DOUBLE_ARRAY,
                      f"{symbol} step when {total} > threshold_high", per_joint=True,
                      minimum=0.0, live=True),
        ]
    return out


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("joint_names", SHARED, Kind.STRING_ARRAY, "joint names, in chain order"),
    Parameter("model.link_masses", SHARED, Kind.DOUBLE_ARRAY, "nominal link masses (kg)",
              per_joint=True, minimum=0.0),
    Parameter("model.link_lengths", SHARED, Kind.DOUBLE_ARRAY, "link lengths (m)",
              per_joint=True, minimum=0.0),
    Parameter("model.radius_proximal", SHARED, Kind.DOUBLE_ARRAY,
              "truncated-cone radius at the proximal joint (m)", per_joint=True, minimum=0.0),
    Parameter("model.radius_distal", SHARED, Kind.DOUBLE_ARRAY,
              "truncated-cone radius at the distal end (m)", per_joint=True, minimum=0.0),
    Parameter("model.joint_axes", SHARED, Kind.STRING_ARRAY,
              "joint axis in the parent link's frame: x, y, z, -x, -y or -z", per_joint=True,
              extra_rule=_axes_rule),
    Parameter("model.gravity", SHARED, Kind.DOUBLE, "gravity acceleration along "
              "model.gravity_direction (m/s^2)", minimum=0.0),
    Parameter("model.gravity_direction", SHARED, Kind.DOUBLE_ARRAY,
              "the direction gravity pulls in, [x, y, z] in the URDF root link's frame (a cone "
              "arm's: Oxyz), any length (it is normalised; model.gravity is the magnitude): "
              "[0, 0, -1] the root's -z (URDFs are drawn z up), [0, -1, 0] a model drawn with y "
              "up; the chain takes it in its base link's frame through the joints above the "
              "base (fixed, or locked at their values)", extra_rule=_direction_rule),
    Parameter("model.source", SHARED, Kind.STRING,
              "where the arm comes from: cones (the paper's truncated cones, the model.link_*, "
              "radius_* and joint_axes keys) or urdf (the chain of model.urdf from base_link to "
              "tip_link; joint_names are its moving joints)", choices=MODEL_SOURCES),
    Parameter("model.urdf", SHARED, Kind.STRING,
              "model.source urdf: the URDF file: a path (relative: to the YAML file that gives "
              "it) or package://name/path (resolved through ament_index)"),
    Parameter("model.base_link", SHARED, Kind.STRING,
              "model.source urdf: the link the chain starts from (fixed to the ground)"),
    Parameter("model.tip_link", SHARED, Kind.STRING,
              "model.source urdf: the link the chain ends at (links beyond it must be fixed or "
              "locked)"),
    Parameter("model.locked_joints", SHARED, Kind.STRING,
              "model.source urdf: joints held at a value, as 'name: value, name: value' (rad, "
              "m for a prismatic joint); empty: none", extra_rule=_locks_problem),
    Parameter("model.urdf_joint_dynamics", SHARED, Kind.STRING,
              "model.source urdf: the URDF's <dynamics damping friction> in the plant: ignore "
              "(the rigid body only) or apply (-b qdot - F tanh(qdot / "
              "patient.friction.stribeck_velocity) at every RK4 stage; the nominal model "
              "leaves them out)", choices=URDF_JOINT_DYNAMICS),
    Parameter("trajectory.start", SHARED, Kind.DOUBLE_ARRAY, "q_d(0) of eq (14) (rad)",
              per_joint=True),
    Parameter("trajectory.goal", SHARED, Kind.DOUBLE_ARRAY, "q_d(T) of eq (14) (rad)",
              per_joint=True),
    Parameter("trajectory.duration", SHARED, Kind.DOUBLE, "T of eq (14) (s)",
              strictly_positive=True),
    Parameter("exercise.name", SHARED, Kind.STRING,
              "the movement (reference) of every trial: paper_quintic (eq (14) from "
              "trajectory.*) or an exercise of exercise.file (core/reference/exercise.py)",
              extra_rule=_name_rule),
    Parameter("exercise.file", SHARED, Kind.STRING,
              "the exercises file (rest points and durations per exercise, sessions); "
              "empty: the shipped config/exercises/default.yaml"),
    Parameter("control.period", SHARED, Kind.DOUBLE,
              "control period (s): effort held over it; the error sums (13) are over its samples",
              strictly_positive=True),
    Parameter("control.period_rule", SHARED, Kind.STRING,
              "fixed: control.period as given; reflex: control.period is the longest period, "
              "shortened to control.period / n so that MAS 3's stretch reflex G T / I stays "
              "below 1 on every patient joint (I its lightest inertia along the reference; "
              "core/loop/rate.py): the paper arm's elbow runs 5 ms, the UR5 and the Panda 10 ms",
              choices=("fixed", "reflex")),
    Parameter("control.kp", SHARED, Kind.DOUBLE_ARRAY, "K_P of eq (11)", per_joint=True,
              minimum=0.0),
    Parameter("control.kd", SHARED, Kind.DOUBLE_ARRAY, "K_D of eq (11)", per_joint=True,
              minimum=0.0),
    Parameter("control.min_stiffness", SHARED, Kind.DOUBLE_ARRAY,
              "absolute stiffness floor (N m/rad) of the feedback on the arm joints a patient's "
              "joint acts on: K_P,j = max(kp_j, min_stiffness_j / I_j), I_j the joint's "
              "lightest inertia along the reference, 1 / max_t (a_N(q_d)^-1)_jj; the floor "
              "capped at (0.8 / control.period)^2 / 4 (core/loop/gains.py); 0: kp as given",
              per_joint=True, minimum=0.0),
    Parameter("control.min_damping", SHARED, Kind.DOUBLE_ARRAY,
              "absolute damping floor (N m s/rad) of the feedback on the arm joints a patient's "
              "joint acts on: K_D,j = max(kd_j, min_damping_j / I_j) (against a delayed stretch "
              "reflex on a light joint); the floor capped at 0.8 / control.period "
              "(core/loop/gains.py); 0: kd as given", per_joint=True, minimum=0.0),
    Parameter("control.velocity_observer", SHARED, Kind.DOUBLE,
              "the velocity eq (11)'s K_D multiplies on the joints whose damping floor "
              "(control.min_damping) raised K_D: an observer's estimate from the measured "
              "position and the command (core/loop/observer.py), its error decaying with this "
              "triple pole (0: deadbeat); 1: off, the measured velocity on every joint; never on "
              "a strapped person (musculoskeletal.model: no sensor model, the true velocity)",
              minimum=0.0, extra_rule=_pole_rule),
    Parameter("control.effort_limit", SHARED, Kind.DOUBLE_ARRAY,
              "|effort| limit per joint (N m)", per_joint=True, strictly_positive=True),
    Parameter("safety.error_envelope", SHARED, Kind.DOUBLE_ARRAY,
              "|e_j| above it aborts the trial at once: safe hold, trial marked aborted, "
              "learned from up to the abort only (abort.*; rad, per joint)", per_joint=True,
              strictly_positive=True, live=True),
    Parameter("safety.hold_kp", SHARED, Kind.DOUBLE_ARRAY,
              "K_P of the safe hold (s^-2, through a_N(q) as control.kp): its stiffness about "
              "the pose latched at an abort, a watchdog trip or a failed homing "
              "(core/loop/hold.py)",
              per_joint=True, minimum=0.0),
    Parameter("safety.hold_kd", SHARED, Kind.DOUBLE_ARRAY,
              "K_D of the safe hold (s^-1, as control.kd): its damping; with hold_kp it must be "
              "stable at control.period with the command one period late (core/loop/hold.py)",
              per_joint=True, minimum=0.0),
    Parameter("safety.hold_ramp", SHARED, Kind.DOUBLE,
              "s over which the safe hold's gains go linearly from control.kp/kd to "
              "safety.hold_kp/kd (rounded to control periods; 0: at once)", minimum=0.0),
    Parameter("safety.watchdog_periods", SHARED, Kind.INTEGER,
              "control periods without /joint_states (controller) or a command (plant) before "
              "the safe hold / zero effort", strictly_positive=True),
    Parameter("watchdog_min_timeout", SHARED, Kind.DOUBLE,
              "wall-clock floor of every watchdog (s; the controller's and the real-time "
              "plant's, core.loop.safety.watchdog_for): a loaded machine may deliver late without "
              "any fault; 0 on hardware", minimum=0.0),
    Parameter("thread_priority", SHARED, Kind.INTEGER,
              "SCHED_FIFO priority of the control loop's threads (the computed-torque "
              "controller's; a plant's in real_time mode), as ros2_control's controller_manager "
              "(nodes/realtime.py); 0: the normal scheduler. Refused without CAP_SYS_NICE or an "
              "rtprio limit: the node says so and runs normally", minimum=0.0,
              extra_rule=_priority_rule),
    Parameter("joint_states_publisher", SHARED, Kind.STRING,
              "the node whose /joint_states the controller and the supervisor act on (others "
              "are refused and reported; wire/publishers.py): plant_simulator (our plants) or "
              "your arm's, e.g. joint_state_broadcaster", extra_rule=_node_name_rule),
    Parameter("protocol", SHARED, Kind.STRING,
              "how a trial starts: services (the plant's reset/start services put it at x_d(0); "
              "our simulator) or homing (the controller brings any arm to q_d(0) and starts "
              "once it settled; core/protocol/homing.py)", choices=("services", "homing")),
    Parameter("homing.speed_limit", CONTROLLER, Kind.DOUBLE,
              "protocol homing: peak joint speed of the homing quintic (rad/s); its duration "
              "is 15/8 max |q_d(0) - q| / speed_limit", strictly_positive=True),
    Parameter("homing.position_tolerance", CONTROLLER, Kind.DOUBLE_ARRAY,
              "protocol homing: |q - q_d(0)| allowed when a trial starts (rad, per joint)",
              per_joint=True, strictly_positive=True),
    Parameter("homing.velocity_tolerance", CONTROLLER, Kind.DOUBLE_ARRAY,
              "protocol homing: |qdot| allowed when a trial starts (rad/s, per joint)",
              per_joint=True, strictly_positive=True),
    Parameter("homing.dwell", CONTROLLER, Kind.DOUBLE,
              "protocol homing: how long the arm must stay within both tolerances before the "
              "trial starts (s); leaving them meanwhile is a fault", minimum=0.0),
    Parameter("homing.timeout", CONTROLLER, Kind.DOUBLE,
              "protocol homing: how long after the path's end the arm may take to settle "
              "before homing fails (s)", strictly_positive=True),
    Parameter("homing.kp", CONTROLLER, Kind.DOUBLE_ARRAY,
              "protocol homing: K_P of homing's own PID (s^-2, through a_N(q) as control.kp); "
              "with kd and ki it must be stable at control.period with the command one period "
              "late (core/params/hold_rule.py)", per_joint=True, minimum=0.0),
    Parameter("homing.kd", CONTROLLER, Kind.DOUBLE_ARRAY,
              "protocol homing: K_D of homing's own PID (s^-1, as control.kd)", per_joint=True,
              minimum=0.0),
    Parameter("homing.ki", CONTROLLER, Kind.DOUBLE_ARRAY,
              "protocol homing: K_I of homing's own PID (s^-3): the integral of q_path - q "
              "takes out the nominal model's gravity error at q_d(0); 0: no integral",
              per_joint=True, minimum=0.0),
    Parameter("homing.integral_limit", CONTROLLER, Kind.DOUBLE_ARRAY,
              "protocol homing: bound on |K_I integral| per joint (rad/s^2, through a_N(q)); "
              "the integral stops there and while any effort is at its limit (anti-windup)",
              per_joint=True, minimum=0.0),
    Parameter("max_missing_samples", SUPERVISOR, Kind.INTEGER,
              "protocol homing: samples of a trial that may be missing (filled by linear "
              "interpolation); a trial missing more is run again, not learned from",
              minimum=0.0),
    Parameter("mass_uncertainty", PLANT, Kind.DOUBLE,
              "delta: the plant's masses are m_i (1 + delta); the controller keeps m_i",
              minimum=-0.9),
    Parameter("integration_step", PLANT, Kind.DOUBLE,
              "RK4 sub-step (s); must divide control.period", strictly_positive=True),
    Parameter("dynamics", PLANT, Kind.STRING,
              "full (true masses, eq (15)) or paper_approximation (eqs (17)-(18), a^-1 a_N ~ I)",
              choices=("full", "paper_approximation")),
    Parameter("mode", PLANT, Kind.STRING,
              "lock_step (advance one period per command: deterministic, as fast as DDS allows) "
              "or real_time (wall-clock timer, the last command held)",
              choices=("lock_step", "real_time")),
    Parameter("real_time_rate", PLANT, Kind.DOUBLE,
              "real_time mode: simulated seconds per wall-clock second (1.0: real time)",
              strictly_positive=True),
    Parameter("pace", PLANT, Kind.DOUBLE,
              "lock_step mode: at most this many simulated seconds per wall-clock second "
              "(1.0: real time, to watch a run live; 0: as fast as it goes); changes no "
              "number, only the wall time (exo-ilc run --live-pace)", minimum=0.0),
    Parameter("clock_every", PLANT, Kind.INTEGER,
              "publish /clock every this many control periods (and at each trial's first "
              "sample); 1: every period", strictly_positive=True),
    *_person_parameters(),
    *_patient_parameters(),
    *drive_parameters(),
    Parameter("law", SUPERVISOR, Kind.STRING,
              "learning law: sign (sgnPDD^2, eq (11)), linear (Arimoto PDD^2-type) or "
              "norm_optimal (model-based, core/learning/norm_optimal.py)",
              choices=("sign", "linear", "norm_optimal"), live=True),
    Parameter("max_trials", SUPERVISOR, Kind.INTEGER, "number of trials to run",
              strictly_positive=True),
    Parameter("error_bound", SUPERVISOR, Kind.DOUBLE, "max |e_j| bound (rad)",
              strictly_positive=True, live=True),
    Parameter("max_late_commands", SUPERVISOR, Kind.DOUBLE,
              "real_time mode: share (0-1) of a trial's control periods the plant may run with "
              "the previous command held (this period's came late) before the trial is run "
              "again instead of learned from", minimum=0.0, extra_rule=_share_rule),
    Parameter("wait_for_recorder", SUPERVISOR, Kind.BOOL,
              "before trial 1, wait until bag_recorder reports it is subscribed to every topic "
              "(exo-ilc run sets it when it records a bag)"),
    Parameter("store.directory", SUPERVISOR, Kind.STRING,
              "root of the store of learned data (every accepted trial and the feed-forward it "
              "led to, core/persistence/store.py); empty: no store (exo-ilc run sets it)"),
    Parameter("store.resume", SUPERVISOR, Kind.BOOL,
              "continue after the last trial in store.directory (false: a store that already "
              "holds trials of this run is an error)"),
    Parameter("profile.initial", SUPERVISOR, Kind.STRING,
              "a patient's profile version file (.npz, core/persistence/profiles.py) whose "
              "feed-forward trial 1 uses (exo-ilc simulate/run --patient set it); empty: "
              "initial_feedforward"),
    Parameter("stop_when_settled", SUPERVISOR, Kind.INTEGER,
              "stop once every joint has stayed within the bound this many trials (0: never)",
              minimum=0.0, live=True),
    # --- learning through an abort (core/session/abort.py, docs/safety.md) ---
    Parameter("abort.backoff", SUPERVISOR, Kind.DOUBLE,
              "after an aborted trial, the learned change on the joints that left the error "
              "envelope is scaled by backoff for the update learned from that trial (0 < b <= 1; "
              "1: no back-off)",
              strictly_positive=True, live=True,
              extra_rule=lambda v: None if v <= 1.0 else
              f"must be in (0, 1] (1: no back-off; 0.5 halves the step), got {v!r}"),
    Parameter("abort.max_consecutive", SUPERVISOR, Kind.INTEGER,
              "stop the session after this many aborted trials in a row, with one message "
              "naming the joint, the time, the error and the likely cause (>= 1)",
              strictly_positive=True),
    # --- end of learning through an abort ---
    Parameter("memory", SUPERVISOR, Kind.STRING,
              "u_{k-1} of eq (11): total_input (feed-forward + feedback) or feedforward",
              choices=("total_input", "feedforward"), live=True),
    Parameter("learning_velocity", SUPERVISOR, Kind.STRING,
              "the velocity the learning step reads from a trial: measured (as the controller "
              "saw it: differentiated and filtered on most arms, so it lags) or position "
              "(central differences of the measured position between trials: zero phase; the "
              "memory's PD part re-formed with it)", choices=("measured", "position")),
    Parameter("initial_feedforward", SUPERVISOR, Kind.STRING,
              "feed-forward of trial 1: zero or reference_acceleration (q_ddot_d)",
              choices=("zero", "reference_acceleration")),
    Parameter("schedule_index", SUPERVISOR, Kind.STRING,
              "M', M'' chosen from their own sums (own_sum) or from |s e| as printed "
              "(position_sum)", choices=("own_sum", "position_sum"), live=True),
    Parameter("error_sum", SUPERVISOR, Kind.STRING,
              "eq (13) sums: abs_of_sum (|sum e|, as printed) or sum_of_abs (sum |e|)",
              choices=("abs_of_sum", "sum_of_abs"), live=True),
    *_schedule_parameters(),
    Parameter("linear.gain_position", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "linear law: learning gain on e", per_joint=True, minimum=0.0, live=True),
    Parameter("linear.gain_velocity", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "linear law: learning gain on e_dot", per_joint=True, minimum=0.0, live=True),
    Parameter("linear.gain_acceleration", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "linear law: learning gain on e_ddot", per_joint=True, minimum=0.0, live=True),
    Parameter("norm_optimal.weight_error", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "norm-optimal law: weight We on the next trial's squared position error, (NO1)",
              per_joint=True, strictly_positive=True, live=True),
    Parameter("norm_optimal.weight_input_change", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "norm-optimal law: weight Wd on the squared change of u_ff between trials "
              "(larger: slower, more robust learning)", per_joint=True, strictly_positive=True,
              live=True),
    Parameter("norm_optimal.weight_input_size", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "norm-optimal law: weight Wu on the squared learned input (0: none; > 0 leaks "
              "u_ff towards 0, raising the floor)", per_joint=True, minimum=0.0, live=True),
    Parameter("norm_optimal.model_kind", SUPERVISOR, Kind.STRING,
              "norm-optimal law's lifted model: per_joint (ZOH double integrator under PD, "
              "as analyze-loop) or linearised (coupled, along the reference, gravity terms of "
              "the mass error included)", choices=("per_joint", "linearised"), live=True),
    Parameter("norm_optimal.model_mass_uncertainty", SUPERVISOR, Kind.DOUBLE,
              "delta_m the norm-optimal model assumes (plant masses m_i (1 + delta_m)); "
              "0: the controller's nominal model", minimum=-0.9, live=True),
    Parameter("norm_optimal.constrained", SUPERVISOR, Kind.BOOL,
              "norm-optimal law: solve each update as a QP that keeps the predicted effort "
              "within control.effort_limit and u_ff within feedforward_limit (Clarabel)",
              live=True),
    Parameter("norm_optimal.effort_margin", SUPERVISOR, Kind.DOUBLE,
              "constrained norm-optimal law: share of control.effort_limit kept free for the "
              "error of the next trial's predicted effort (0.01: the QP aims at 99 %)",
              minimum=0.0, live=True, extra_rule=_margin_rule),
    Parameter("norm_optimal.uncertainty_range", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "[low, high] mass uncertainty the norm-optimal weights must tolerate: "
              "analyze-loop warns when they do not", minimum=-0.9, extra_rule=_range_rule),
    Parameter("q_filter.enabled", SUPERVISOR, Kind.BOOL,
              "zero-phase low-pass Q applied to the learned feed-forward after every update",
              live=True),
    Parameter("q_filter.cutoff_hz", SUPERVISOR, Kind.DOUBLE,
              "Q-filter cut-off (Hz, Butterworth design; |Q| = 1/2 there after filtfilt); "
              "below the Nyquist frequency 1 / (2 control.period)", strictly_positive=True,
              live=True),
    Parameter("q_filter.order", SUPERVISOR, Kind.INTEGER,
              "Q-filter Butterworth order (run forwards and backwards: twice the roll-off)",
              strictly_positive=True, live=True),
    Parameter("feedforward_limit", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "bound on |learned feed-forward| per joint (rad/s^2, the units of u); 0: no bound",
              per_joint=True, minimum=0.0, live=True),
    Parameter("progress_gain.position", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "extra position learning gain per joint (units of u per rad): the update adds "
              "Q[G e] while the joint's max |e| is a new low by more than progress_gain.margin "
              "(core/learning/progress_gain.py); 0: off", per_joint=True, minimum=0.0),
    Parameter("progress_gain.margin", SUPERVISOR, Kind.DOUBLE,
              "share by which a trial's max |e| must beat the lowest so far for "
              "progress_gain to act", minimum=0.0, extra_rule=_margin_rule),
    Parameter("averaging.memory", SUPERVISOR, Kind.DOUBLE,
              "trials over which the law's step gain K is estimated from the lag-1 "
              "autocorrelation of its target's trial-to-trial changes (the local-level Kalman "
              "gain: core/learning/averaging.py); u_ff,k+1 = u_ff,k + K (T_k - u_ff,k); 0: off "
              "(K = 1, the plain law)", minimum=0.0, extra_rule=_averaging_memory_rule),
    Parameter("averaging.min_gain", SUPERVISOR, Kind.DOUBLE,
              "the least step gain K averaging may set (the law never stops learning)",
              minimum=0.0, extra_rule=_fraction_rule),
    Parameter("assist_as_needed.enabled", SUPERVISOR, Kind.BOOL,
              "assist-as-needed (core/learning/assist.py, Emken et al. 2007): forgetting factor "
              "and error deadband around the law", live=True),
    Parameter("assist_as_needed.forgetting", SUPERVISOR, Kind.DOUBLE,
              "f of u_k+1 = f u_k + G(e) (learned step): the learned input decays by f per "
              "trial unless the error calls for it (1: no forgetting)", live=True,
              extra_rule=_forgetting_rule),
    Parameter("assist_as_needed.variability", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "sigma: the patient's own trial-to-trial variability of the position error (rad) "
              "per joint; 0: no deadband", per_joint=True, minimum=0.0, live=True),
    Parameter("assist_as_needed.deadband_sigmas", SUPERVISOR, Kind.DOUBLE,
              "deadband half-width in sigmas: |e| below it is not learned (Emken: 3)",
              minimum=0.0, live=True),
    Parameter("assist_as_needed.transition_sigmas", SUPERVISOR, Kind.DOUBLE,
              "width of the tanh transition at the deadband's edge, in sigmas (Emken: 0.5)",
              strictly_positive=True, live=True),
    Parameter("identification.enabled", SUPERVISOR, Kind.BOOL,
              "identify the patient's joint forces between trials (viscous, Coulomb, stiffness, "
              "reflex; core/learning/identification.py): reported per trial"),
    Parameter("identification.forgetting", SUPERVISOR, Kind.DOUBLE,
              "lambda per trial of the recursive least squares: memory ~1 / (1 - lambda) trials",
              extra_rule=_forgetting_rule),
    Parameter("identification.in_loop", SUPERVISOR, Kind.BOOL,
              "computed torque adds the identified joint forces along the reference, eqs "
              "(9)/(16) with eq (6)'s terms (core/learning/patient_model.py); needs "
              "identification.enabled"),
    Parameter("identification.first_trial", SUPERVISOR, Kind.INTEGER,
              "the first trial that may run with identified joint forces (the estimate of the "
              "trials before it)", strictly_positive=True),
    Parameter("identification.trust_limit", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "N m per joint: bound on the identified joint forces computed torque adds",
              per_joint=True, minimum=0.0),
    Parameter("identification.max_change", SUPERVISOR, Kind.DOUBLE_ARRAY,
              "N m per joint: the most the added joint forces may change at any sample from "
              "one trial to the next (a trust region)", per_joint=True, minimum=0.0),
    Parameter("identification.adoption", SUPERVISOR, Kind.STRING,
              "what the learned feed-forward does when the added joint forces change: restart "
              "(a joint adopted for the first time starts from the law's first feed-forward: "
              "what it had learned of the patient would count twice), handover (it gives up "
              "a_N(q_d)^-1 times the change: the total input never jumps) or keep",
              choices=("restart", "handover", "keep")),
    Parameter("identification.inverse_gain", SUPERVISOR, Kind.DOUBLE,
              "g: after the law's update the feed-forward adds g a_N(q_d)^-1 (K e + B e_dot) "
              "with the identified stiffness K and damping B (the update then inverts the arm "
              "with the patient; 0: off)", minimum=0.0),
    Parameter("identification.rebuild_threshold", SUPERVISOR, Kind.DOUBLE,
              "norm-optimal's model is rebuilt about the identified patient when its linearised "
              "forces moved by more than this share since the last build", minimum=0.0),
    Parameter("identification.mass_error", SUPERVISOR, Kind.BOOL,
              "the added forces include the identified mass error times the nominal torque "
              "along the reference (eq (15): a uniform mass error is exactly this term)"),
    Parameter("identification.relative_precision", SUPERVISOR, Kind.DOUBLE,
              "largest 95 % half-width over |value| of a parameter the loop may use (below "
              "the identification's absolute floor it is always precise enough)",
              strictly_positive=True),
    Parameter("identification.reversal_speed", SUPERVISOR, Kind.DOUBLE,
              "rad/s: Coulomb friction is fitted only from samples where the joint moves "
              "faster than this (a smooth and a hard law agree there) and told from the offset "
              "only on a joint that did both ways; else the offset carries it (0: the tanh law "
              "trusted at every speed)", minimum=0.0),
    Parameter("identification.voluntary", SUPERVISOR, Kind.BOOL,
              "fit the patient's own effort toward the reference too (for a patient known to "
              "push; else its suspicion makes an estimate untrustworthy)"),
    *musculoskeletal_parameters(),
)

BY_NAME: Mapping[str, Parameter] = {p.name: p for p in PARAMETERS}


def parameters_of(node: str) -> tuple[Parameter, ...]:
    """The parameters a node declares: the shared ones and its own section's."""
    return tuple(p for p in PARAMETERS if p.section in (SHARED, node))
