"""The virtual patient (core/loop/patient.py): each effect against a hand computation or an
independent integrator, the node's plant stepper against the compiled trial, per-trial draws,
measured vs true error, resume, validation, and graph == in-process under ``realistic``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from exo_ilc_ros.core.arm.joint_forces import passive_effort_into
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.loop.controller import GuardedControlStep
from exo_ilc_ros.core.loop.patient import (
    MAS_PRESETS,
    PatientLearning,
    PatientModel,
    PatientTrial,
    measure_into,
    patient_period,
    true_error,
)
from exo_ilc_ros.core.loop.plant import (
    PlantIntegration,
    plant_integration,
    rk4_period,
    rk4_period_with_joint_forces,
)
from exo_ilc_ros.core.loop.stepper import PlantStepper
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import load_config, scenario_names, scenario_path
from exo_ilc_ros.core.persistence.store import learning_key
from exo_ilc_ros.core.programs.study import (
    StudyCell,
    resolve_law,
    resolve_scenario,
    run_cell,
    study_cells,
)
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.sim.experiment import Experiment

SHORT = {"trajectory.duration": 1.0}
SHIPPED = ("ideal", "sensor", "friction", "spastic", "voluntary", "realistic", "learning")


def _config(scenario: str = "ideal", **overrides: Any) -> Any:
    return load_config(overlays=[scenario_path(scenario)], overrides={**SHORT, **overrides})


def test_shipped_scenarios_load_and_only_ideal_is_off() -> None:
    assert set(SHIPPED) <= set(scenario_names())
    for name in SHIPPED:
        model = PatientModel(_config(name))
        assert model.enabled == (name != "ideal"), name
        assert model.measures == (name in ("sensor", "realistic")), name


def test_ideal_is_the_shipped_run_bit_for_bit() -> None:
    """Every effect off: the same doubles as without the patient parameters' scenario, no true
    state apart, and the store's learning key of a config without them."""
    plain = run_trials(load_config(overrides=SHORT), 0.05, 4)
    ideal = run_trials(_config("ideal"), 0.05, 4)
    for a, b in zip(plain.records, ideal.records, strict=True):
        assert np.array_equal(a.position, b.position) and np.array_equal(a.effort, b.effort)
        assert b.true_position is None
        np.testing.assert_array_equal(b.true_max_abs_error, b.max_abs_error)
    config = _config("ideal")
    seeded = config.replace({"patient.seed": 5})  # no effect on: not keyed
    reference = Experiment(config).reference
    assert learning_key(config, reference) == learning_key(seeded, reference)
    noisy = config.replace({"patient.sensor.position_noise": 1e-4})
    assert learning_key(noisy, reference) != learning_key(config, reference)


def test_sensor_quantises_adds_noise_and_differentiates() -> None:
    """By hand: resolution 0.01 rad, noise given per sample, velocity as the difference of
    the measured positions over T = 0.01 s, then a first-order filter a = T / (tau + T)."""
    config = _config("ideal", **{"patient.sensor.quantisation": 0.01,
                                 "patient.sensor.differentiate_velocity": True,
                                 "patient.sensor.velocity_filter": 0.01})
    scalars = PatientModel(config).scalars
    noise = np.zeros((2, 3, 3))
    noise[0, 1] = [1e-4, 0.0, -1e-4]
    noise[1, 1] = [0.5, 0.0, 0.0]
    memory = np.zeros((3, 3))
    q_m, qd_m = np.empty(3), np.empty(3)
    measure_into(0, np.array([0.004, 0.016, -0.026]), np.array([9.0, 9.0, 9.0]), scalars,
                 noise, memory, q_m, qd_m)
    np.testing.assert_allclose(q_m, [0.0, 0.02, -0.03], atol=1e-15)
    np.testing.assert_array_equal(qd_m, [0.0, 0.0, 0.0])  # no earlier sample: 0
    measure_into(1, np.array([0.012, 0.016, -0.041]), np.array([9.0, 9.0, 9.0]), scalars,
                 noise, memory, q_m, qd_m)
    np.testing.assert_allclose(q_m, [0.0101, 0.02, -0.0401], atol=1e-15)
    raw = np.array([(0.0101 - 0.0) / 0.01 + 0.5, 0.0, (-0.0401 + 0.03) / 0.01])
    np.testing.assert_allclose(qd_m, 0.5 * raw, rtol=1e-12)  # a = 0.01 / (0.01 + 0.01)


def test_passive_forces_by_hand() -> None:
    config = _config("ideal", **{"patient.friction.viscous": [0.1, 0.2, 0.0],
                                 "patient.friction.coulomb": [0.18, 0.0, 0.1],
                                 "patient.friction.stribeck_velocity": 0.05,
                                 "patient.passive.stiffness": [1.0, 0.0, 2.0],
                                 "patient.passive.rest_position": [0.0, 0.0, 0.3]})
    model = PatientModel(config)
    q, qd = np.array([0.5, 0.1, 0.2]), np.array([0.04, -1.0, -0.02])
    out = np.empty(3)
    passive_effort_into(q, qd, np.array([1.0, 2.0, 3.0]), model.joint, 1.0 / 0.05, out)
    expected = [1.0 - 0.1 * 0.04 - 0.18 * np.tanh(0.8) - 1.0 * 0.5,
                2.0 - 0.2 * -1.0,
                3.0 - 0.1 * np.tanh(-0.4) - 2.0 * (0.2 - 0.3)]
    np.testing.assert_allclose(out, expected, rtol=1e-14)


def test_passive_rk4_matches_an_independent_integrator() -> None:
    """One period with friction, stiffness and a held effort, against scipy's adaptive RK45 on
    a(q) qdd = Q + passive(q, qdot) - c(q, qdot) (the arm model's own forward dynamics)."""
    config = _config("friction")
    ex = Experiment(config)
    model = PatientModel(config)
    q0, qd0 = np.array([0.3, 0.2, 0.4]), np.array([0.5, -0.3, 0.8])
    effort = np.array([2.0, -1.0, 0.5])

    def rhs(_: float, x: np.ndarray) -> np.ndarray:
        q, qd = x[:3], x[3:]
        total = np.empty(3)
        passive_effort_into(q, qd, effort, model.joint, 1.0 / 0.1, total)
        return np.concatenate([qd, ex.plant.forward_dynamics(q, qd, total)])

    exact = solve_ivp(rhs, (0.0, ex.period), np.concatenate([q0, qd0]), rtol=1e-12,
                      atol=1e-14).y[:, -1]
    integration = plant_integration(ex.period, ex.substeps, ex.plant.kernel_args,
                                    ex.nominal.kernel_args, 0)
    q, qd = q0.copy(), qd0.copy()
    rk4_period_with_joint_forces(q, qd, effort, integration, True, model.joint,
                                 model.scalars[2], np.empty(3))
    np.testing.assert_allclose(np.concatenate([q, qd]), exact, atol=1e-9)
    # without the joint forces: rk4_period's doubles exactly, whatever the joint array holds
    plain_q, plain_qd = q0.copy(), qd0.copy()
    rk4_period(plain_q, plain_qd, effort, integration)
    q, qd = q0.copy(), qd0.copy()
    rk4_period_with_joint_forces(q, qd, effort, integration, False, model.joint,
                                 model.scalars[2], np.empty(3))
    assert np.array_equal(q, plain_q) and np.array_equal(qd, plain_qd)
    assert not np.array_equal(q, exact[:3])


def test_held_torque_delay_reflex_and_voluntary_by_hand() -> None:
    """:func:`patient_period`'s held torque at sample 3: the command of sample 3 - d, the
    reflex on the velocity d_r samples ago, and the lagged voluntary torque."""
    config = _config("ideal", **{"patient.effort_delay": 2,
                                 "patient.spasticity.reflex_gain": [1.5, 0.0, 0.0],
                                 "patient.spasticity.reflex_threshold": [0.2, 0.0, 0.0],
                                 "patient.spasticity.reflex_delay": 0.02,
                                 "patient.voluntary.stiffness": [0.0, 4.0, 0.0],
                                 "patient.voluntary.damping": [0.0, 1.0, 0.0],
                                 "patient.voluntary.time_constant": 0.03})
    ex = Experiment(config)
    model = PatientModel(config)
    ref = ex.reference
    history = np.zeros((2, ref.samples, 3))
    history[0, 1] = [-0.7, 0.0, 0.0]  # the velocity the reflex sees at i = 3 (d_r = 2)
    history[1, 1] = [1.0, 2.0, 3.0]  # the command applied at i = 3 (d = 2)
    memory = np.zeros((3, 3))
    memory[0, 1] = 0.2  # the voluntary torque so far
    held = np.empty(3)
    q, qd = ref.position[3] + [0.0, -0.01, 0.0], ref.velocity[3].copy()
    trial_scalars = np.array([0.8, 2.0])  # gain 0.8, the patient 2 samples ahead
    q_start = q.copy()
    patient_period(3, q, qd, np.zeros(3), _integration(ex),
                   _patient(ex, model, trial_scalars, history, memory, held))
    raw = 0.8 * (4.0 * (ref.position[5, 1] - q_start[1]) + 1.0 * (ref.velocity[5, 1]
                                                                     - ref.velocity[3, 1]))
    voluntary = 0.2 + 0.25 * (raw - 0.2)  # a = 0.01 / (0.03 + 0.01)
    np.testing.assert_allclose(held, [1.0 + 1.5 * 0.5, 2.0 + voluntary, 3.0], rtol=1e-12)


def _integration(ex: Experiment) -> PlantIntegration:
    return plant_integration(ex.period, ex.substeps, ex.plant.kernel_args,
                             ex.nominal.kernel_args, 0)


def _patient(ex: Experiment, model: PatientModel, trial_scalars: np.ndarray,
             history: np.ndarray, memory: np.ndarray, held: np.ndarray) -> PatientTrial:
    """A :class:`PatientTrial` on ``ex``'s reference with these arrays (no noise, no offset,
    no learned torque)."""
    ref = ex.reference
    return PatientTrial(ref.position, ref.velocity, model.joint, model.scalars,
                        np.zeros((2, 0, 0)), np.zeros((2, 0)), trial_scalars, np.zeros((0, 0)),
                        history, memory, held, np.empty(3))


def _reflex_torque(config: Any, velocity: list[float]) -> np.ndarray:
    """The torque :func:`patient_period` holds over sample 0 with no command and the true
    velocity ``velocity`` (reflex delay 0: the reflex sees it at once): the reflex alone."""
    ex = Experiment(config)
    model = PatientModel(config)
    ref = ex.reference
    held = np.empty(3)
    patient_period(0, ref.position[0].copy(), np.array(velocity), np.zeros(3), _integration(ex),
                   _patient(ex, model, np.array([1.0, 0.0]), np.zeros((2, ref.samples, 3)),
                            np.zeros((3, 3)), held))
    return held


def test_reflex_is_clipped_at_its_ceiling_by_hand() -> None:
    """-sgn(v) min(G max(0, |v| - v_th), R): 0 at or below the threshold, G (|v| - v_th) up to
    the ceiling R, then R, against the stretch; R = 0 is no ceiling."""
    config = _config("ideal", **{"patient.spasticity.reflex_gain": [2.0, 2.0, 2.0],
                                 "patient.spasticity.reflex_threshold": [0.5, 0.5, 0.5],
                                 "patient.spasticity.reflex_max": [1.0, 1.0, 0.0],
                                 "patient.spasticity.reflex_delay": 0.0})
    np.testing.assert_array_equal(_reflex_torque(config, [0.4, -0.5, 0.5]), [0.0, 0.0, 0.0])
    # 0.9 rad/s: 2 x 0.4 = 0.8 < 1; -3 rad/s: 2 x 2.5 = 5 > 1 -> 1; no ceiling on joint 3: 5
    np.testing.assert_allclose(_reflex_torque(config, [-3.0, 0.9, -3.0]), [1.0, -0.8, 5.0],
                               rtol=1e-15)
    np.testing.assert_allclose(_reflex_torque(config, [3.0, -0.9, 3.0]), [-1.0, 0.8, -5.0],
                               rtol=1e-15)
    np.testing.assert_allclose(_reflex_torque(config, [1.0, -1.0, 1.0]), [-1.0, 1.0, -1.0],
                               rtol=1e-15)  # 2 x 0.5 = the ceiling exactly
    grade = PatientModel(_config("spastic"))
    g, th, ceiling = MAS_PRESETS["2"][2:]
    assert ceiling == pytest.approx(g * (np.pi - th), abs=0.05)  # the reflex at 180 deg/s
    np.testing.assert_array_equal(grade.joint[8], [ceiling] * 3)


def test_the_reflex_ceiling_keeps_the_safe_hold_finite() -> None:
    """The tuned sign law under ``spastic`` at 15 %: with the MAS 2 reflex unbounded (the
    preset's values as ``custom``, no ceiling) and the safe hold on the controller's gains (as
    before ``safety.hold_*``) the hold after the envelope abort of trial 169 runs away to a
    non-finite state (the study's FAILED cell before the ceiling; it was trial 161 at 10 %
    until the quintic's coefficients became exact, issue 25: the run is chaotic in the last
    bits); the shipped hold's damping keeps even the unbounded reflex finite; with the preset's
    ceiling (at 10 %) the envelope aborts trials too, and every trial stays finite."""
    law, scenario = resolve_law("tuned"), resolve_scenario("spastic")
    k, b, g, th, _ = MAS_PRESETS["2"]
    [unbounded] = study_cells([law], [scenario], [0.15], [0], 169)
    values = {**unbounded.values, "patient.spasticity.mas_grade": "custom",
              "patient.spasticity.stiffness": [k] * 3, "patient.spasticity.damping": [b] * 3,
              "patient.spasticity.reflex_gain": [g] * 3,
              "patient.spasticity.reflex_threshold": [th] * 3}
    soft = {**values, "safety.hold_kp": values["control.kp"],
            "safety.hold_kd": values["control.kd"], "safety.hold_ramp": 0.0}
    old = run_cell(StudyCell("tuned", "spastic", 0.15, 0, soft))
    assert old.aborted and old.nonfinite is not None and "safe hold" in old.nonfinite
    held = run_cell(StudyCell("tuned", "spastic", 0.15, 0, values))
    assert held.aborted == old.aborted and held.nonfinite is None
    [bounded] = study_cells([law], [scenario], [0.1], [0], 220)  # aborts there too
    new = run_cell(bounded)
    # the safe hold ran; three aborts in a row stop the run (abort.max_consecutive)
    assert new.aborted == [215, 216, 217] and new.true_max_abs_error.shape[0] == 217
    assert new.nonfinite is None and new.failure is None
    assert np.all(np.isfinite(new.max_abs_effort)) and np.all(new.max_abs_effort <= 40.0)

def test_mas_grade_sets_the_preset() -> None:
    config = _config("spastic")
    k, b, g, th, ceiling = MAS_PRESETS["2"]
    joint = PatientModel(config).joint
    np.testing.assert_array_equal(joint[2], [k] * 3)  # stiffness (no passive stiffness here)
    np.testing.assert_array_equal(joint[0], [b] * 3)  # damping (no friction here)
    np.testing.assert_array_equal(joint[4], [g] * 3)
    np.testing.assert_array_equal(joint[5], [th] * 3)
    np.testing.assert_array_equal(joint[8], [ceiling] * 3)
    assert _config("ideal", **{"patient.spasticity.mas_grade": 2})[
        "patient.spasticity.mas_grade"] == "2"  # YAML's unquoted 2


def test_draws_depend_only_on_seed_and_trial() -> None:
    model = PatientModel(_config("realistic"))
    a, b = model.draws(7, 101), model.draws(7, 101)
    assert np.array_equal(a.noise, b.noise) and np.array_equal(a.initial, b.initial)
    assert not np.array_equal(model.draws(8, 101).noise, a.noise)
    other = PatientModel(_config("realistic", **{"patient.seed": 1}))
    assert not np.array_equal(other.draws(7, 101).noise, a.noise)
    assert model.fatigue(1) == 1.0
    assert model.fatigue(1001) == pytest.approx(0.7 + 0.3 * np.exp(-1.0))


@pytest.mark.parametrize("scenario", ["realistic", "sensor", "spastic", "voluntary",
                                      "learning"])
def test_plant_stepper_is_the_compiled_trial_bit_for_bit(scenario: str) -> None:
    """The node's stepper (begin_trial, measure, step) with the controller's step gives the
    doubles of :func:`simulate_trial_guarded` (measured, true, effort) for trials 1 to 3, the
    stepper's own learning patient against the in-process one (trial 2 run twice: a rerun)."""
    ex = Experiment(_config(scenario))
    ref = ex.reference
    u_ff = np.random.default_rng(3).standard_normal(ref.position.shape) * 0.5
    learning = PatientLearning(ex.patient, ref.samples)
    stepper, control = PlantStepper(ex), GuardedControlStep(ex)
    last_error: dict[int, np.ndarray] = {}
    for trial in (1, 2, 2, 3):
        while learning.learned_through < trial - 1:  # learn from the last run of each trial
            done = learning.learned_through + 1
            learning.learn(done, last_error[done])
        record = ex.run_trial(u_ff, trial, None, learning.torque)
        stepper.begin_trial(trial)
        measured, true, efforts = [], [], []
        for i in range(ref.samples):
            true.append(stepper.position.copy())
            q, qd = stepper.measure()
            measured.append(q.copy())
            efforts.append(control(u_ff[i], ref.position[i], ref.velocity[i], q, qd).copy())
            if i + 1 < ref.samples:
                stepper.step(efforts[-1])
        assert record.aborted_at is None
        assert np.array_equal(np.array(measured), record.position)
        assert np.array_equal(np.array(efforts), record.effort)
        expected_true = record.position if record.true_position is None \
            else record.true_position
        assert np.array_equal(np.array(true), expected_true)
        last_error[trial] = true_error(record)
    assert ex.patient.learns == (scenario == "learning")
    if scenario == "learning":
        assert learning.learned_through == 2 and np.any(learning.torque != 0.0)


def test_learning_patient_two_state_by_hand_and_resumed(tmp_path: Path) -> None:
    """After trial 1 the patient adds (B_f + B_s) K_e e_1; after trial 2
    (A_f B_f + B_f) K_e e_1 ... by the recursion; a resumed in-process run rebuilds the
    patient's state from the stored true errors and continues bit for bit."""
    config = _config("learning")
    model = PatientModel(config)
    learning = PatientLearning(model, 101)
    e1, e2 = np.full((101, 3), 0.01), np.full((101, 3), -0.02)
    learning.learn(1, e1)
    gain = np.array(config["patient.learning.gain"])
    np.testing.assert_allclose(learning.torque, (0.06 + 0.02) * gain * e1, rtol=1e-14)
    learning.learn(2, e2)
    fast = 0.92 * 0.06 * gain * e1 + 0.06 * gain * e2
    slow = 0.995 * 0.02 * gain * e1 + 0.02 * gain * e2
    np.testing.assert_allclose(learning.torque, fast + slow, rtol=1e-13)
    with pytest.raises(ValueError):
        learning.learn(4, e1)
    whole = run_trials(config, 0.05, 4)
    run_trials(config, 0.05, 2, store=tmp_path)
    resumed = run_trials(config, 0.05, 4, store=tmp_path, resume=True)
    for a, b in zip(whole.records, resumed.records, strict=True):
        assert np.array_equal(a.position, b.position) and np.array_equal(a.effort, b.effort)
    plain = run_trials(config.replace({"patient.learning.gain": [0.0, 0.0, 0.0]}), 0.05, 4)
    assert not np.array_equal(plain.records[-1].position, whole.records[-1].position)


def test_true_error_is_the_plants_and_iterations_use_it() -> None:
    result = run_trials(_config("sensor"), 0.05, 3)
    record = result.records[-1]
    assert record.true_position is not None and record.true_velocity is not None
    assert not np.array_equal(record.position, record.true_position)
    np.testing.assert_array_equal(
        record.true_max_abs_error,
        np.max(np.abs(record.reference.position - record.true_position), axis=0))
    assert np.array_equal(result.true_max_abs_errors()[-1], record.true_max_abs_error)
    friction = run_trials(_config("friction"), 0.05, 2)
    assert friction.records[-1].true_position is None  # exact sensors: no state apart


def test_resume_reproduces_the_patient_run(tmp_path: Path) -> None:
    config = _config("realistic")
    whole = run_trials(config, 0.05, 4)
    run_trials(config, 0.05, 2, store=tmp_path)
    resumed = run_trials(config, 0.05, 4, store=tmp_path, resume=True)
    assert resumed.resumed == 2
    for a, b in zip(whole.records, resumed.records, strict=True):
        assert np.array_equal(a.position, b.position)
        assert a.true_position is not None and b.true_position is not None
        assert np.array_equal(a.true_position, b.true_position)


@pytest.mark.parametrize(("yaml_body", "key", "rule"), [
    ("sensor:\n        position_noise: -1.0e-4", "patient.sensor.position_noise", ">= 0"),
    ("friction:\n        viscous: [-0.1, 0.0, 0.0]", "patient.friction.viscous", ">= 0"),
    ("effort_delay: 1.5", "patient.effort_delay", "integer"),
    ("spasticity:\n        reflex_delay: -0.1", "patient.spasticity.reflex_delay", ">= 0"),
    ("spasticity:\n        mas_grade: \"4\"", "patient.spasticity.mas_grade", "one of"),
    ("spasticity:\n        mas_grade: \"2\"\n        damping: [0.1, 0.0, 0.0]",
     "patient.spasticity.damping", "either a mas_grade"),
    ("spasticity:\n        reflex_max: [2.0, -1.0, 0.0]", "patient.spasticity.reflex_max", ">= 0"),
    ("spasticity:\n        mas_grade: \"1\"\n        reflex_max: [2.0, 2.0, 2.0]",
     "patient.spasticity.reflex_max", "either a mas_grade"),
    ("sensr:\n        quantisation: 1.0e-4", "patient.sensr.quantisation", "unknown"),
    ("seed: -1", "patient.seed", ">= 0"),
])
def test_bad_scenario_values_name_file_key_and_rule(tmp_path: Path, yaml_body: str, key: str,
                                                    rule: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("plant_simulator:\n  ros__parameters:\n    patient:\n      "
                    + yaml_body + "\n")
    with pytest.raises(ConfigError) as caught:
        load_config(overlays=[scenario_path(path)])
    assert caught.value.key == key and caught.value.source == str(path)
    assert rule in caught.value.rule


def test_every_patient_parameter_is_in_the_plant_section() -> None:
    """... but for where the patient's joints lie on the arm (patient.joints, joint_zero): the
    arm's, shared, since the length of every per-joint patient list depends on them."""
    names = [p for p in schema.PARAMETERS if p.name.startswith("patient.")]
    shared = {schema.PATIENT_JOINTS, "patient.joint_zero"}
    assert names and all(not p.live for p in names)
    assert all((p.section == schema.SHARED) == (p.name in shared) for p in names)
    assert all(p.section == schema.PLANT for p in names if p.name not in shared)


class _Plant:
    """The graph as the protocol sees it: the in-process trial answered sample by sample,
    the measured samples, the controller's ``done``, then the true samples (one of them lost
    in the first attempt)."""

    def __init__(self, config: Any) -> None:
        self.experiment = Experiment(config)
        self.protocol: Any = None
        self.t0 = 0
        self.pushed: list[tuple[int, np.ndarray]] = []
        self.records: list[Any] = []
        self.events: list[tuple[str, dict[str, str]]] = []
        self.drop_true = 5

    def reset(self) -> None:
        self.t0 += 10_000_000_000
        self.protocol.on_reset(self.t0)

    def push_feedforward(self, trial: int, t0_ns: int, feedforward: np.ndarray,
                         joint_force: np.ndarray | None = None) -> None:
        self.pushed.append((trial, feedforward.copy()))
        self.protocol.on_acknowledged(trial, t0_ns)

    def start(self) -> None:
        pass

    def publish_conclusion(self, conclusion: Any, end_ns: int) -> None:
        record = conclusion.record  # its arrays are the protocol's buffers: copied now
        self.records.append((record.trial, record.position.copy(),
                             record.true_position.copy(), record.effort.copy()))

    def event(self, message: str, values: Any, stamp_ns: int | None = None) -> None:
        self.events.append((message, dict(values)))

    def log(self, error: bool, text: str) -> None:
        pass

    def run_trial(self) -> None:
        protocol = self.protocol
        protocol.on_started(True)
        trial, ff = self.pushed[-1]
        record = self.experiment.run_trial(ff, trial, protocol.session.levels)
        step = protocol.samples.step_ns
        for i in range(record.position.shape[0]):
            protocol.on_sample(self.t0 + i * step, record.position[i], record.velocity[i])
        protocol.on_done(trial, self.t0, {"watchdog_trips": "0", "aborted_at": "-1"})
        assert len(self.records) < trial, "ended before its true samples were in"
        assert record.true_position is not None and record.true_velocity is not None
        for i in range(record.position.shape[0]):
            if i == self.drop_true:
                self.drop_true = -1
                continue
            protocol.on_true_sample(self.t0 + i * step, record.true_position[i],
                                    record.true_velocity[i])


def test_protocol_waits_for_the_true_samples_and_reruns_a_trial_that_lost_one() -> None:
    from exo_ilc_ros.core.protocol.trial_protocol import Phase, TrialProtocol

    config = _config("sensor", max_trials=3)
    plant = _Plant(config)
    protocol = TrialProtocol(config, plant, clock=lambda: 0.0)
    plant.protocol = protocol
    protocol.open({"mass_uncertainty": config["mass_uncertainty"]})
    protocol.tick(graph_ready=True)
    for _ in range(5):
        if protocol.phase is Phase.FINISHED:
            break
        plant.run_trial()
    assert protocol.phase is Phase.FINISHED
    assert ("aborted", {"trial": "1", "reason": "lost", "lost_true": "1"}) in plant.events
    local = run_trials(config)
    assert [r[0] for r in plant.records] == [1, 2, 3]
    for (_, position, true_position, effort), ref in zip(plant.records, local.records,
                                                         strict=True):
        assert np.array_equal(position, ref.position)
        assert ref.true_position is not None
        assert np.array_equal(true_position, ref.true_position)
        assert np.array_equal(effort, ref.effort)


@pytest.mark.graph
def test_graph_equals_in_process_under_realistic(tmp_path: Path) -> None:
    """3 trials of ``realistic`` and of ``learning`` through the graph: measured and true
    max |e|, u_ff and effort of every trial equal the in-process run to 1e-9 (the plant's
    draws come from the trial number in the feed-forward's frame, the learning patient lives
    in the plant). ``ideal`` (every effect off: an empty overlay) is not run through the graph
    here: test_ideal_is_the_shipped_run_bit_for_bit gives it the plain config's doubles, and
    the plain config through the graph equals in-process bit for bit in test_reliability.py
    (``_same_as_in_process``) and test_hostile.py."""
    from exo_ilc_ros.orchestration.graph import run_graph

    for name, tolerance in (("realistic", 1e-9), ("learning", 1e-9)):
        config = _config(name, max_trials=3)
        local = run_trials(config)
        graph = run_graph(config, timeout=300.0).summary
        np.testing.assert_allclose(graph.max_abs_error, local.max_abs_errors, rtol=0.0,
                                   atol=tolerance, err_msg=name)
        np.testing.assert_allclose(graph.true_errors, local.true_max_abs_errors(), rtol=0.0,
                                   atol=tolerance, err_msg=name)
        assert graph.max_abs_feedforward is not None and graph.max_abs_effort is not None
        np.testing.assert_allclose(graph.max_abs_feedforward, local.max_abs_feedforward,
                                   rtol=0.0, atol=tolerance, err_msg=name)
        np.testing.assert_allclose(graph.max_abs_effort, local.max_abs_effort, rtol=0.0,
                                   atol=tolerance, err_msg=name)
        assert (graph.true_max_abs_error is not None) == (name == "realistic")
        if name == "realistic":
            assert not np.array_equal(graph.true_errors, graph.max_abs_error)
    json.dumps(graph.to_json())  # the summary exports


def test_bag_of_a_patient_run_keeps_the_true_error_and_replays_exactly(tmp_path: Path) -> None:
    """A `sensor` run written as a bag: its summary has the measured and the true tables, and
    `simulate --replay` (the bag's config, patient included) reproduces every trial."""
    from exo_ilc_ros.bag import read_bag, write_run
    from exo_ilc_ros.bag.replay import replay

    config = _config("sensor")
    result = run_trials(config, 0.05, 3)
    write_run(tmp_path / "bag", config, result)
    run = read_bag(tmp_path / "bag")
    summary = run.summary()
    assert summary.true_max_abs_error is not None
    np.testing.assert_array_equal(summary.true_max_abs_error, result.true_max_abs_errors())
    np.testing.assert_array_equal(summary.max_abs_error, result.max_abs_errors)
    assert replay(run).identical
