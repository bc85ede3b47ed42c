"""Issue 33, honest identification: Coulomb friction and the offset on a movement that never
reverses are reported as not separately identifiable, the offset carrying c + F_c sgn(qdot),
and the loop uses only that combination; on a movement that reverses every joint, Coulomb
friction is fitted from the fast samples only, where a smooth and a hard (MuJoCo's
``frictionloss``) law agree, and is within 10 % of a hard law's."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core import Experiment, load_config
from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.learning.identification import JointForceIdentifier
from exo_ilc_ros.core.learning.identification_settings import IdentificationSettings
from exo_ilc_ros.core.learning.joint_force_term import joint_force_term
from exo_ilc_ros.core.loop.controller import GuardedControlStep
from exo_ilc_ros.core.loop.trial import record_from_samples
from exo_ilc_ros.core.params.config import config_dir, scenario_path
from exo_ilc_ros.core.session.learning_session import LearningSession, run_trials

REVERSAL = 0.2
FRICTION = {"viscous": 0.14, "coulomb": 0.18, "stiffness": 1.0}  # scenarios/friction.yaml


def _identify(records: Any, config: Any) -> Any:
    identifier = JointForceIdentifier(build_arm(config), IdentificationSettings.from_config(
        config, reversal_speed=REVERSAL))
    estimate = None
    for record in records:
        estimate = identifier.update_record(record)
    return estimate


def test_one_way_movement_reports_friction_and_offset_inseparable() -> None:
    """The paper's movement never reverses: on the shoulder flexion (0.59 rad/s one way) the
    Coulomb friction is left out, named, and the offset carries c + F_c = 0 + 0.18 (within
    10 % of F_c); the rest position is not separately identifiable; the elbow (0.20 rad/s)
    reports damping and Coulomb friction as not separable. In the JSON too. The joint-force
    term adds no Coulomb term for the left-out friction (0 in its place)."""
    config = load_config(overlays=[scenario_path("friction")])
    records = run_trials(config, 0.05, 5).records
    estimate = _identify(records, config)
    shoulder = estimate.joints[0]
    assert shoulder.absorbed == ("coulomb",)
    assert shoulder.inseparable[0][:2] == ("offset", "coulomb")
    assert math.isnan(shoulder.inseparable[0][2])
    assert not shoulder["coulomb"].identifiable and math.isnan(shoulder.value("coulomb"))
    assert "not separately identifiable from offset" in shoulder["coulomb"].reason
    assert shoulder["offset"].combined_with == ("coulomb",)
    assert abs(shoulder.value("offset") - FRICTION["coulomb"]) <= 0.1 * FRICTION["coulomb"]
    assert not shoulder["rest_position"].identifiable
    elbow = estimate.joints[2]
    assert ("viscous", "coulomb") in [pair[:2] for pair in elbow.inseparable]
    assert not elbow["viscous"].trustworthy and not elbow["coulomb"].trustworthy
    plain = json.loads(json.dumps(estimate.as_dict()))
    first = plain["joints"][0]
    assert first["inseparable"][0] == {"kept": "offset", "left_out": "coulomb",
                                       "correlation": None}
    assert first["parameters"]["offset"]["combined_with"] == ["coulomb"]
    ref = records[0].reference
    term = joint_force_term(estimate, ref.position, ref.velocity, 1e3,
                            IdentificationSettings(reversal_speed=REVERSAL))
    if term.used[0]:  # only the combination: K q + offset + B qdot, no tanh term
        j = shoulder
        expected = (j.value("viscous") * ref.velocity[:, 0]
                    + j.value("stiffness") * ref.position[:, 0] + j.value("offset"))
        np.testing.assert_allclose(term.torque[:, 0], expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("scenarios", [("friction",), ("friction", "sensor")],
                         ids=["friction", "friction+sensor"])
def test_reversing_exercise_separates_friction(scenarios: tuple[str, ...]) -> None:
    """config/patient_aware.yaml (reversal_speed 0.2) on config/exercises
    reach_and_return_identify, which reverses every joint above 0.4 rad/s: every joint used,
    no pair inseparable, B, F_c, K identifiable and within 10 % on every joint (with a 14-bit
    encoder too)."""
    config = load_config(overlays=[config_dir() / "patient_aware.yaml",
                                   *[scenario_path(s) for s in scenarios]],
                         overrides={"exercise.name": "reach_and_return_identify"})
    result = run_trials(config, 0.1, 6)
    estimate = result.joint_forces[6].estimate
    assert np.all(result.joint_forces[6].used)
    for joint in estimate.joints:
        assert joint.inseparable == () and joint.absorbed == (), joint.inseparable
        for name, true in FRICTION.items():
            assert joint[name].identifiable, (joint.joint, name, joint[name].reason)
            assert abs(joint.value(name) - true) <= 0.1 * true, (joint.joint, name)


def test_the_summary_the_tables_and_the_json_name_what_is_not_separable() -> None:
    """patient_aware on the paper's movement: the trial summary's
    ``identified/inseparable/<joint>`` says the offset carries the Coulomb friction, the key
    reads back from the summary and the profile JSON, and ``exo-ilc analyze``'s table and
    ``simulate``'s final lines print it."""
    from exo_ilc_ros.analysis.identified import format_final, format_table
    from exo_ilc_ros.core.programs.identified import Identified

    config = load_config(overlays=[config_dir() / "patient_aware.yaml",
                                   scenario_path("friction")])
    step = run_trials(config, 0.1, 3).joint_forces[3]
    names = list(config["joint_names"])
    shown = Identified.from_step(step, names)
    values = dict(shown.summary_values())
    text = values[f"identified/inseparable/{names[0]}"]
    assert text.startswith("offset carries coulomb (never reversed)"), text
    assert "viscous ~ coulomb (too slow for the friction law)" in \
        values[f"identified/inseparable/{names[2]}"]
    again = Identified.from_summary(3, values, names)
    assert again is not None and again.joints[0].inseparable == text
    assert Identified.from_json(json.loads(json.dumps(shown.to_json()))).joints[0] \
        .inseparable == text
    assert f"not separately identifiable (only the combination is used): {text}" in \
        format_table([shown], names)
    assert text in format_final(shown, "run")
    assert not step.used[0]


def _lab(exercise: str, trials: int, period_rule: str = "reflex") -> tuple[list[Any], list[Any]]:
    """patient_aware driven from outside on MuJoCo (damping 0.4, frictionloss 0.3, stiffness
    1 toward 0 / 0 / 0.3 on every joint, 10 % heavier than the model): each trial from rest
    at q_d(0), the controller's effort from the measured state, the record rebuilt from the
    samples as a lab's would be (bench/mujoco_identification_bench.py). ``period_rule``
    ``reflex`` (patient_aware.yaml's): 5 ms on this arm; ``fixed``: 10 ms."""
    from exo_ilc_ros.core.sim.mujoco_arm import MujocoArm

    overrides: dict[str, Any] = {
        "mass_uncertainty": 0.1, "patient.friction.viscous": [0.4] * 3,
        "patient.friction.coulomb": [0.3] * 3, "patient.passive.stiffness": [1.0] * 3,
        "patient.passive.rest_position": [0.0, 0.0, 0.3], "control.period_rule": period_rule}
    if exercise:
        overrides["exercise.name"] = exercise
    config = load_config(overlays=[config_dir() / "patient_aware.yaml"], overrides=overrides)
    experiment = Experiment(config)
    session = LearningSession(config)
    arm = MujocoArm.from_config(config)
    control = GuardedControlStep(experiment)
    ref = experiment.reference
    records, steps = [], []
    while not session.finished and session.trial <= trials:
        feedforward, force = session.feedforward, session.joint_force
        arm.set_state(ref.position[0], ref.velocity[0])
        control.begin_trial()
        q_log, qd_log = np.empty(ref.position.shape), np.empty(ref.position.shape)
        aborted = None
        for i in range(ref.samples):
            q_log[i], qd_log[i] = arm.position, arm.velocity
            if control.sample(i, feedforward[i], ref.position[i], ref.velocity[i], q_log[i],
                              qd_log[i], False, None if force is None else force[i]) \
                    and aborted is None:
                aborted = i
            if i + 1 < ref.samples:
                arm.step(control.effort.copy())
        record = record_from_samples(experiment, session.trial, feedforward, q_log, qd_log,
                                     session.levels, aborted_at=aborted, joint_force=force)
        records.append(record)
        steps.append(session.conclude(record).joint_forces)
    return records, steps


TRUTH = {"viscous": 0.4, "coulomb": 0.3, "stiffness": 1.0}


def test_mujoco_hard_friction_one_way_nothing_confidently_wrong() -> None:
    """The paper's movement on MuJoCo's hard friction: before, F_c came out 0.01 for 0.3 and
    the loop used it. Now every parameter the loop uses (a joint in use: its viscous,
    stiffness, and Coulomb friction unless left out) is within 10 % of MuJoCo's; the offset of
    a joint whose friction was left out is within 10 % of F_c (rest 0: c + F_c = 0.3); and
    patient_aware is within 0.005 rad by trial 10 (measured: trial 7, nothing used)."""
    records, steps = _lab("", 10)
    assert np.max(np.abs(records[9].error)) <= 0.005
    for step in steps:
        for joint in step.estimate.joints:
            if "coulomb" in joint.absorbed and joint["offset"].trustworthy \
                    and joint.joint < 2:
                assert abs(joint.value("offset") - 0.3) <= 0.03, joint.value("offset")
            if not step.used[joint.joint]:
                continue
            for name, true in TRUTH.items():
                if name not in joint.absorbed:
                    assert abs(joint.value(name) - true) <= 0.1 * true, (joint.joint, name)


def test_mujoco_hard_friction_reversing_within_ten_percent() -> None:
    """reach_and_return_identify on MuJoCo's hard friction: after 3 trials every joint is
    used, with B, F_c and K within 10 % of MuJoCo's joint attributes (measured: within 4 %),
    and patient_aware is within 0.005 rad by trial 10 (measured: trial 5; trial 6 on,
    3.7e-3 falling to 1.1e-3 at trial 10; with the update inverting the tanh's Coulomb
    secant at the reversals too: above the bound through trial 10)."""
    records, steps = _lab("reach_and_return_identify", 10)
    assert any(np.max(np.abs(r.error)) <= 0.005 for r in records[:10])
    assert np.max(np.abs(records[9].error)) <= 0.005
    last = steps[2]
    assert np.all(last.used), last.reasons
    for joint in last.estimate.joints:
        assert joint.inseparable == ()
        for name, true in TRUTH.items():
            assert abs(joint.value(name) - true) <= 0.1 * true, (joint.joint, name,
                                                                   joint.value(name))


def _binomial_floor(n: int, rate: float = 0.95, z: float = 3.29) -> float:
    """The least count of n intervals of coverage ``rate`` that holds the truth, short of a
    two-sided 99.9 % normal bound on the binomial (z 3.29): below it the stated rate is
    rejected."""
    return n * rate - z * math.sqrt(n * rate * (1.0 - rate))


def _coverage(estimates: Any, truth: dict[str, float]) -> tuple[int, int, float]:
    """(intervals holding the truth, intervals, sd of (estimate - truth) / SE) over every
    joint's identifiable, separately fitted B, F_c, K."""
    held, z = [], []
    for estimate in estimates:
        for joint in estimate.joints:
            for name, true in truth.items():
                p = joint[name]
                if p.identifiable and not p.combined_with and math.isfinite(p.low):
                    held.append(p.low <= true <= p.high)
                    z.append((p.value - true) / p.total_error)
    return int(np.sum(held)), len(held), float(np.std(z))


def test_intervals_cover_at_their_rate_on_our_plant() -> None:
    """30 seeded trials of the friction patient with a 14-bit encoder and 2e-4 rad of noise,
    on the reversing exercise, PD alone, each identified on its own (reversal_speed 0.2, no
    reflex grid): the
    95 % intervals (autocorrelation-robust, Newey-West) hold the truth in at least the
    binomial floor of 95 % (99.9 % two-sided bound: n 180 -> 162.6, i.e. 90.3 %), and are not
    more than 3 times too wide (sd of the standardised error > 1/3). Measured: 100 / 100 /
    97.5 %, sd 0.52-0.70 (the residual's misfit widens them)."""
    config = load_config(overlays=[scenario_path("friction"), scenario_path("sensor")],
                         overrides={"exercise.name": "reach_and_return_identify",
                                    "mass_uncertainty": 0.05,
                                    "patient.sensor.position_noise": 2e-4})
    experiment = Experiment(config)
    feedforward = np.zeros(experiment.reference.position.shape)
    estimates = []
    for seed in range(30):
        identifier = JointForceIdentifier(build_arm(config), IdentificationSettings.from_config(
            config, reversal_speed=REVERSAL, reflex=False))
        estimates.append(identifier.update_record(experiment.run_trial(feedforward, seed + 1)))
    held, n, spread = _coverage(estimates, FRICTION)
    assert n >= 150 and held >= _binomial_floor(n), (held, n)
    assert spread > 1.0 / 3.0, spread


def _mujoco_coverage(period_rule: str) -> tuple[int, int, float]:
    """Trial 2 of patient_aware on MuJoCo's hard friction (the reversing exercise), identified
    through 30 seeded 14-bit encoders (random offset) with 2e-4 rad of noise: (held, n, sd)."""
    records, _ = _lab("reach_and_return_identify", 2, period_rule)
    record = records[-1]
    config = load_config(overrides={"exercise.name": "reach_and_return_identify",  # the
                                    # period the record ran at
                                    "control.period": record.reference.period})
    count = 2.0 * np.pi / 2 ** 14
    estimates = []
    for seed in range(30):
        rng = np.random.default_rng(seed)
        noisy = record.position + 2e-4 * rng.standard_normal(record.position.shape)
        measured = np.round(noisy / count + rng.uniform(-0.5, 0.5, (1, 3))) * count
        identifier = JointForceIdentifier(build_arm(config), IdentificationSettings.from_config(
            config, reversal_speed=REVERSAL, reflex=False))
        estimates.append(identifier.update(measured, record.effort, 1))
    return _coverage(estimates, TRUTH)


def test_intervals_cover_at_their_rate_on_mujoco_hard_friction() -> None:
    """MuJoCo's damping 0.4, hard frictionloss 0.3 and stiffness 1 (a Coulomb law the model's
    tanh is not), patient_aware's second trial at 10 ms (``control.period_rule: fixed``): the
    95 % intervals of B, F_c, K hold MuJoCo's values in at least the binomial floor of 95 %
    (n 270 -> 245.3, i.e. 90.9 %). Measured: 95.7 / 91.5 / 99.1 %."""
    held, n, spread = _mujoco_coverage("fixed")
    assert n >= 240 and held >= _binomial_floor(n), (held, n)
    assert spread > 1.0 / 3.0, spread


def test_intervals_cover_at_their_rate_on_mujoco_hard_friction_at_5_ms() -> None:
    """The same at the 5 ms patient_aware.yaml's period rule runs the paper arm: twice the
    samples shrink the noise's standard errors by ~sqrt(2), and the tanh law's bias against
    MuJoCo's hard one (B 0.394, F_c 0.303, as at 10 ms) does not shrink. Without the model
    error (the hard-law refit's shift) 231 of 270 held it (85.6 %: B 81 %, F_c 76 %)."""
    held, n, spread = _mujoco_coverage("reflex")
    assert n >= 240 and held >= _binomial_floor(n), (held, n)
    assert spread > 1.0 / 3.0, spread
