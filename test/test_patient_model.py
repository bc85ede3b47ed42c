"""The identified patient in the loop (core/learning/patient_model.py, the session's use of it,
config/patient_aware.yaml): the rules checked by hand on in-process runs of the virtual patient,
whose truth is known."""

from __future__ import annotations

import copy
import dataclasses
import functools
import itertools
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.errors import SafetyError
from exo_ilc_ros.core.learning.norm_optimal_model import PatientLinearisation, build_lifted_model
from exo_ilc_ros.core.learning.patient_model import JointForceModel
from exo_ilc_ros.core.learning.progress_gain import ProgressGain
from exo_ilc_ros.core.learning.qfilter import qfilter_of
from exo_ilc_ros.core.loop.gains import feedback_gains, velocity_observer_gains
from exo_ilc_ros.core.loop.observer import fed_back_velocity
from exo_ilc_ros.core.loop.record import position_velocity_record
from exo_ilc_ros.core.params.config import Config, config_dir, load_config, scenario_path
from exo_ilc_ros.core.session.learning_session import LearningSession, run_trials
from exo_ilc_ros.core.sim.experiment import Experiment

AWARE = config_dir() / "patient_aware.yaml"
PAPER_GAINS = {"control.kp": [16.0, 10.0, 10.0], "control.kd": [8.0, 5.0, 7.0],
               "control.min_stiffness": 0.0, "control.min_damping": 0.0,
               "progress_gain.position": [0.0, 0.0, 5.0], "feedforward_limit": 100.0}
"""patient_aware.yaml before issue 33 (the paper's PD gains; the progress gain on the elbow
only: 100 against K_P 10 would make the factor 10 at 0 Hz). Under the stiffer PD (225 / 30) the
patient moves the arm less off the reference, and the friction patient's estimate is trusted
only after trial 3 (with these: after trial 2), and the velocity's lag leaves a repeating error
~ tau K_D / K_P qddot_d five times smaller (K_D / K_P 0.13 against 0.7). The tests of the
identification's rules that count on an early trust, and of the lag's bias, run with these."""


def _config(scenario: str, **overrides: Any) -> Config:
    """patient_aware.yaml with the tanh friction law trusted at every speed
    (``identification.reversal_speed`` 0): the rules of the loop are checked on the paper's
    movement, which never reverses, where the shipped 0.2 leaves Coulomb friction to the
    offset and nothing may be used (test_identification_honest.py). At 100 Hz
    (``control.period_rule: fixed``, the shipped rule runs this arm at 5 ms): the checks below
    form the session's update from the config's own gains and Q-filter."""
    return load_config(overlays=[AWARE, scenario_path(scenario)],
                       overrides={"mass_uncertainty": 0.1, "control.period_rule": "fixed",
                                  "identification.reversal_speed": 0.0, **overrides})


def _learned_from(config: Config, record: Any) -> Any:
    """The record the session learns from (patient_aware.yaml's ``learning_velocity:
    position``: the velocity from the measured position)."""
    if config["learning_velocity"] != "position":
        return record
    gains = velocity_observer_gains(config)  # the velocity the controller fed back
    fed_back = fed_back_velocity(record.position, record.velocity, record.control_input,
                                 gains) if np.any(gains[0]) else None
    return position_velocity_record(record, feedback_gains(config)[1], fed_back)


@functools.cache
def _friction_run(trials: int = 4) -> Any:
    return run_trials(_config("friction"), trials=trials)


def test_forces_phase_in_within_the_trust_limits() -> None:
    """Trial 1 adds nothing; once the estimate is trustworthy (after trial 2 for friction with
    the patient's own effort fitted: trial 1 cannot tell it from the stiffness) the forces
    follow it, never beyond +-trust_limit and never moving by more than max_change at any
    sample from one trial to the next; they are what the estimate gives along the
    reference."""
    config = _config("friction", **PAPER_GAINS)
    records = run_trials(config, trials=4).records
    limit = np.asarray(config["identification.trust_limit"])
    step = np.asarray(config["identification.max_change"])
    assert not np.any(records[0].joint_force)
    assert np.any(records[2].joint_force)
    for before, after in itertools.pairwise(records):
        assert np.all(np.abs(after.joint_force) <= limit)
        assert np.all(np.abs(after.joint_force - before.joint_force) <= step + 1e-12)
    # the friction scenario's elbow by hand: B qdot + F_c tanh(qdot / 0.1) + K (q - 0.3)
    ref = records[0].reference
    elbow = 0.14 * ref.velocity[:, 2] + 0.18 * np.tanh(ref.velocity[:, 2] / 0.1) \
        + 1.0 * (ref.position[:, 2] - 0.3)
    np.testing.assert_allclose(records[3].joint_force[:, 2], elbow, atol=0.01)


def test_the_handover_keeps_the_total_input() -> None:
    """adoption: handover: when the forces change by d tau the learned feed-forward gives up
    a_N(q_d)^-1 d tau (a_N from the model's metric tensor, solved here independently)."""
    config = _config("friction", **{"identification.inverse_gain": 0.0,
                                    "progress_gain.position": 0.0})
    session = LearningSession(config)
    experiment = Experiment(config)
    nominal = build_arm(config)
    ref = session.reference
    law = session.active_law
    for _ in range(3):
        record = experiment.run_trial(session.feedforward, session.trial, session.levels, None,
                                      session.joint_force)
        before = session.joint_force.copy()
        plain = law.update(_learned_from(config, record)).feedforward  # the law alone (no state)
        conclusion = session.conclude(record)
        change = conclusion.update.joint_force - before
        given_up = np.array([np.linalg.solve(nominal.metric_tensor(q), d)
                             for q, d in zip(ref.position, change, strict=True)])
        np.testing.assert_allclose(conclusion.update.feedforward, plain - given_up,
                                   rtol=1e-10, atol=1e-10)


def test_the_update_inverts_the_arm_with_the_identified_patient() -> None:
    """inverse_gain g: the update adds g Q[a_N(q_d)^-1 (tau_p(q_d, qdot_d) - tau_p(q, qdot))]
    (Q the law's Q-filter; after the handover), for friction by hand:
    K e + B e_dot + F_c (tanh(qdot_d / v_s) - tanh(qdot / v_s)) with the estimate's K, B, F_c."""
    config = _config("friction", **{"identification.voluntary": False,
                                    "progress_gain.position": 0.0,
                                    # K_P 225 / K_D 30 on the elbow too: with the floors'
                                    # 1600 / 80 the elbow moves less and is trusted a trial
                                    # later (the rule checked is the same)
                                    "control.min_stiffness": 0.0, "control.min_damping": 0.0})
    session = LearningSession(config)
    experiment = Experiment(config)
    nominal = build_arm(config)
    for _ in range(3):
        record = experiment.run_trial(session.feedforward, session.trial, session.levels, None,
                                      session.joint_force)
        before = session.joint_force.copy()
        plain = session.active_law.update(_learned_from(config, record)).feedforward
        conclusion = session.conclude(record)
    assert not record.aborted
    record = _learned_from(config, record)
    change = conclusion.update.joint_force - before
    plain = plain - np.array([np.linalg.solve(nominal.metric_tensor(q), d)  # the handover
                              for q, d in zip(record.reference.position, change, strict=True)])
    forces = conclusion.joint_forces
    assert forces is not None and np.all(forces.used)
    estimate = forces.estimate
    assert not any(j.reflex_detected and j["reflex_gain"].trustworthy for j in estimate.joints)
    k, b, f = (estimate.values(name) for name in ("stiffness", "viscous", "coulomb"))
    v_s = 0.1
    torque = k * record.error + b * record.error_velocity + f * (
        np.tanh(record.reference.velocity / v_s) - np.tanh(record.velocity / v_s))
    added = np.array([np.linalg.solve(nominal.metric_tensor(q), t)
                      for q, t in zip(record.reference.position, torque, strict=True)])
    qfilter = qfilter_of(config)
    assert qfilter is not None
    np.testing.assert_allclose(conclusion.update.feedforward, plain + qfilter.apply(added),
                               rtol=1e-9, atol=1e-9)


def test_an_ill_conditioned_identification_changes_nothing_in_the_loop() -> None:
    """A movement that never moves (goal = start): nothing is identifiable, so the loop runs
    exactly as without the patient model (every record equal bit for bit) and every step says
    why no force is used."""
    still = {"trajectory.goal": [0.0, 0.0, 0.0]}
    aware = run_trials(_config("friction", **still), trials=4)
    plain = run_trials(_config("friction", **still, **{"identification.in_loop": False}),
                       trials=4)
    for a, b in zip(aware.records, plain.records, strict=True):
        np.testing.assert_array_equal(a.effort, b.effort)
        np.testing.assert_array_equal(a.feedforward, b.feedforward)
        assert not np.any(a.joint_force)
    session = LearningSession(_config("friction", **still))
    experiment = Experiment(session.config)
    for _ in range(3):
        record = experiment.run_trial(session.feedforward, session.trial, session.levels, None,
                                      session.joint_force)
        forces = session.conclude(record).joint_forces
        assert forces is not None and not np.any(forces.used)
        assert all(forces.reasons)


def test_a_non_finite_or_absurd_estimate_never_reaches_the_controller() -> None:
    """An estimate marked trustworthy but holding NaN, or a stiffness far beyond its plausible
    range, adds nothing beyond the trust limit: NaN is refused (the forces stay), the absurd
    value is held at its range and clamped to trust_limit; a non-finite profile is refused by
    the trial itself."""
    config = _config("friction", **PAPER_GAINS)
    records = run_trials(config, trials=4).records
    model = JointForceModel(config, build_arm(config), records[0].reference)
    model.conclude(records[0])
    model.conclude(records[1])
    kept = model.joint_force.copy()
    estimate = model.identifier.estimate
    assert estimate is not None

    def broken(value: float) -> Any:
        joints = []
        for joint in estimate.joints:
            parameters = dict(joint.parameters)
            parameters["stiffness"] = dataclasses.replace(parameters["stiffness"], value=value)
            joints.append(dataclasses.replace(joint, parameters=parameters, trustworthy=True,
                                              reasons=()))
        return dataclasses.replace(estimate, joints=tuple(joints))

    identifier = model.identifier
    for value in (float("nan"), 1e6):
        identifier.update_record = lambda record, v=value: broken(v)  # type: ignore[method-assign]
        step = model.conclude(records[2])
        assert np.all(np.isfinite(model.joint_force))
        assert np.all(np.abs(model.joint_force) <= config["identification.trust_limit"])
        if np.isnan(value):
            np.testing.assert_array_equal(model.joint_force, kept)
            assert all(r == "non-finite estimate" for r in step.reasons)
    bad = np.zeros_like(records[0].position)
    bad[7, 1] = np.inf
    with pytest.raises(SafetyError, match="joint forces"):
        Experiment(config).run_trial(records[0].feedforward, 1, None, None, bad)


@pytest.mark.parametrize("law", ["linear", "norm_optimal"])
def test_resume_gives_the_same_trials_with_the_patient_in_the_loop(tmp_path: Path,
                                                                   law: str) -> None:
    """A run stored after 2 trials and resumed equals the run in one go: the identification is
    replayed from the stored trials (norm-optimal's model rebuilt as it was) and the stored
    forces are used exactly."""
    config = _config("friction", law=law)
    whole = run_trials(config, trials=4)
    run_trials(config, trials=2, store=tmp_path)
    resumed = run_trials(config, trials=4, store=tmp_path, resume=True)
    assert resumed.resumed == 2
    for a, b in zip(whole.records, resumed.records, strict=True):
        np.testing.assert_array_equal(a.effort, b.effort)
    np.testing.assert_array_equal(whole.final.joint_force, resumed.final.joint_force)
    np.testing.assert_array_equal(whole.final.feedforward, resumed.final.feedforward)


@pytest.mark.parametrize("scenario", ["friction", "spastic"])
def test_patient_aware_learns_a_patient_within_ten_trials(scenario: str) -> None:
    """The shipped law's claim at 10 %: every joint's true max |e| within 0.005 rad in at most
    10 trials, no abort (robust.yaml alone needs 55 trials for friction and never gets there
    for spastic in 60: docs/patient-identification.md)."""
    result = run_trials(_config(scenario), trials=10)
    assert not any(r.aborted for r in result.records)
    assert np.all(result.records[-1].true_max_abs_error <= 0.005)


def test_norm_optimal_model_about_the_patient_predicts_the_patients_arm() -> None:
    """The lifted model rebuilt about the friction scenario's patient (its true K, B, F_c
    linearised along the reference) predicts how the patient's arm answers a small change of
    the feed-forward at least five times better than the nominal model (plant without mass
    error, model assuming none)."""
    config = load_config(overlays=[scenario_path("friction")], overrides={
        "law": "norm_optimal", "mass_uncertainty": 0.0,
        "norm_optimal.model_mass_uncertainty": 0.0, "trajectory.duration": 2.0})
    experiment = Experiment(config)
    ref = experiment.reference
    base = np.zeros(ref.position.shape)
    rng = np.random.default_rng(0)
    change = 1e-3 * np.cumsum(rng.standard_normal(ref.position.shape), axis=0) / 10.0
    moved = (experiment.run_trial(base + change, 1).position
             - experiment.run_trial(base, 1).position).ravel()
    v = ref.velocity
    patient = PatientLinearisation(np.full(v.shape, 1.0),
                                   0.14 + 0.18 / 0.1 / np.cosh(v / 0.1) ** 2)
    nominal = build_lifted_model(config).g @ change.ravel()
    about = build_lifted_model(config, patient).g @ change.ravel()
    assert np.linalg.norm(about - moved) * 5.0 < np.linalg.norm(nominal - moved)


def test_norm_optimal_is_rebuilt_about_the_identified_patient_when_it_moves() -> None:
    """With law: norm_optimal the session rebuilds the model when the forces are adopted and
    again only when their linearisation moves by more than rebuild_threshold; each rebuild is
    a note of the update."""
    config = load_config(overlays=[scenario_path("friction")], overrides={
        "law": "norm_optimal", "mass_uncertainty": 0.1, "identification.enabled": True,
        "identification.in_loop": True, "identification.rebuild_threshold": 0.1})
    result = run_trials(config, trials=6)
    rebuilt = [k for k, notes in result.notes.items()
               if any("rebuilt about the identified patient" in n for n in notes)]
    assert rebuilt and rebuilt[0] <= 2
    assert len(rebuilt) < 5  # not every trial: the estimate settles within 10 %
    assert np.all(result.records[-1].true_max_abs_error <= 0.005)


def test_position_velocity_record_differences_the_measured_position() -> None:
    """The re-read record's velocity is the central difference of its measured position (exact
    on a quadratic, where the lagging measured velocity is not), and its control input is the
    one the controller would have formed with it: u + K_D (qdot_measured - qdot_position)."""
    record = _friction_run().records[-1]
    t = np.arange(record.position.shape[0])[:, None] * record.reference.period
    position = 0.3 * t ** 2 + np.array([0.0, 0.1, -0.2])
    lagging = 0.6 * np.maximum(t - 0.015, 0.0) * np.ones(3)
    record = dataclasses.replace(record, position=position, velocity=lagging)
    kd = np.array([8.0, 5.0, 7.0])
    reread = position_velocity_record(record, kd)
    np.testing.assert_allclose(reread.velocity[1:-1], 0.6 * t[1:-1] * np.ones(3), atol=1e-12)
    np.testing.assert_allclose(reread.control_input,
                               record.control_input + kd * (lagging - reread.velocity))
    np.testing.assert_array_equal(reread.position, record.position)


def test_learning_from_the_position_velocity_lowers_the_sensor_floor() -> None:
    """Under ``sensor`` (a raw backward difference: qdot lags half a period) a law that learns
    from the measured velocity keeps a repeating error ~ tau K_D / K_P qddot_d; learning from
    the position's central differences (patient_aware.yaml's ``learning_velocity: position``)
    removes it: the settled true error is less than 0.6 of the other's (docs/patient-aware.md:
    9.1e-4 against 3.9e-4 rad over 1000 trials)."""
    def settled(velocity: str) -> float:
        result = run_trials(_config("sensor", learning_velocity=velocity, **PAPER_GAINS),
                            trials=30)
        worst = [float(np.max(r.true_max_abs_error)) for r in result.records[-10:]]
        assert not any(r.aborted for r in result.records)
        return float(np.median(worst))

    measured, position = settled("measured"), settled("position")
    assert position < 0.6 * measured, (position, measured)


def test_progress_gain_acts_only_while_the_error_makes_new_lows(tmp_path: Path) -> None:
    """progress_gain (PG): a joint gets Q[G e] after a trial whose max |e| beats the lowest so
    far by more than the margin, nothing once it stops falling; the session adds exactly that
    to the law's update, and a run resumed from the store rebuilds the lowest error."""
    rule = ProgressGain(np.array([0.0, 0.0, 5.0]), 0.02)
    np.testing.assert_array_equal(rule.active(np.array([1.0, 1.0, 1.0]), None), [True] * 3)
    np.testing.assert_array_equal(rule.active(np.array([0.5, 0.99, 0.97]),
                                              np.array([1.0, 1.0, 1.0])), [True, False, True])
    error = np.ones((5, 3))
    assert rule.step(error, np.array([True, True, False])) is None  # no gain on joints 1, 2
    np.testing.assert_array_equal(rule.step(error, np.array([False, False, True])),
                                  np.tile([0.0, 0.0, 5.0], (5, 1)))

    config = _config("friction", **{"progress_gain.position": [0.0, 0.0, 5.0]})
    plain_config = _config("friction", **{"progress_gain.position": 0.0})
    with_gain, plain = LearningSession(config), LearningSession(plain_config)
    experiment = Experiment(config)
    qfilter = qfilter_of(config)
    assert qfilter is not None
    lowest = None
    for _ in range(4):
        record = experiment.run_trial(with_gain.feedforward, with_gain.trial, with_gain.levels,
                                      None, with_gain.joint_force)
        plain.next_update = with_gain.next_update  # the same state, without the gain
        plain.joint_forces = copy.deepcopy(with_gain.joint_forces)
        plain.trial = with_gain.trial
        expected = plain.conclude(record).update.feedforward
        active = rule.active(record.max_abs_error, lowest)
        lowest = record.max_abs_error.copy() if lowest is None else np.minimum(
            lowest, record.max_abs_error)
        if active[2]:
            expected = expected + qfilter.apply(np.where(active, [0.0, 0.0, 5.0], 0.0)
                                                * record.error)
        np.testing.assert_allclose(with_gain.conclude(record).update.feedforward, expected,
                                   rtol=1e-12, atol=1e-12)
    whole = run_trials(config, trials=6)
    run_trials(config, trials=3, store=tmp_path)
    resumed = run_trials(config, trials=6, store=tmp_path, resume=True)
    np.testing.assert_array_equal(whole.final.feedforward, resumed.final.feedforward)
