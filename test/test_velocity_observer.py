"""The velocity observer the feedback uses on the joints the gains' floors raised
(``control.velocity_observer``, core/loop/observer.py, issue 33): hand-computed estimates, where
it is on, that a trial's commands are formed again exactly from its samples, and the rule of
its value."""

from __future__ import annotations

import numpy as np
import pytest

from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.loop.gains import velocity_observer_gains
from exo_ilc_ros.core.loop.observer import (
    fed_back_velocity,
    feedback_velocity_into,
    observer_gains,
    observer_state,
    remember_command,
)
from exo_ilc_ros.core.loop.trial import record_from_samples
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.sim.experiment import Experiment

T = 0.01
A = 3.0  # rad/s^2


def _estimates(position: np.ndarray, command: np.ndarray, pole: float) -> np.ndarray:
    """v^ of one joint at every sample (the measured velocity 0 throughout: only the
    observer's estimate can be right)."""
    gains = observer_gains(np.array([pole]), np.array([True]), T)
    state = observer_state(1)
    out = np.empty(position.shape[0])
    one = np.empty(1)
    for i, q in enumerate(position):
        feedback_velocity_into(i, np.array([q]), np.zeros(1), gains, state, one)
        remember_command(i, gains, state, np.array([command[i]]))
        out[i] = one[0]
    return out


def test_an_unknown_constant_acceleration_is_tracked_in_three_samples() -> None:
    """q = A t^2 / 2 with no command (A unknown to the observer), deadbeat (p = 0: l_q 1,
    l_v 3/2, l_d 1). By hand: sample 1, r = A T^2 / 2, v^ = 3/2 r / T = 0.75 A T, d^ = A / 2;
    sample 2, predicted q 0.5 + 0.75 + 0.25 = 1.5 A T^2 against 2 A T^2, so v^ = 0.75 A T +
    0.5 A T + 0.75 A T = 2 A T (exact), d^ = A; sample 3 on: predicted exactly, v^ = i A T."""
    times = T * np.arange(8)
    v = _estimates(0.5 * A * times ** 2, np.zeros(8), 0.0)
    assert v[0] == 0.0
    assert v[1] == pytest.approx(0.75 * A * T, rel=1e-12)
    assert v[2] == pytest.approx(2.0 * A * T, rel=1e-12)
    assert np.allclose(v[3:], A * times[3:], rtol=1e-11, atol=0.0)


def test_a_joint_held_at_rest_by_its_command_is_estimated_at_rest() -> None:
    """A command u = 5 rad/s^2 that only holds the joint against a patient's pull (q stays 0):
    d^ starts at -u_0, so every prediction is q = 0 (residual 0) and v^ is exactly 0 at every
    sample, whatever the pole."""
    for pole in (0.0, 0.5):
        v = _estimates(np.zeros(6), np.full(6, 5.0), pole)
        assert np.array_equal(v, np.zeros(6))


def test_a_motion_the_command_explains_is_tracked_after_its_start() -> None:
    """q = A t^2 / 2 under the command u = A: d^ starts at -A (the joint taken at rest) for a
    true unknown acceleration 0, the residuals are those of the test above, so deadbeat
    v^_1 = 0.75 A T, then v^_i = i A T from sample 2 on."""
    times = T * np.arange(8)
    v = _estimates(0.5 * A * times ** 2, np.full(8, A), 0.0)
    assert v[1] == pytest.approx(0.75 * A * T, rel=1e-12)
    assert np.allclose(v[2:], A * times[2:], rtol=1e-11, atol=0.0)


def test_a_slower_pole_tracks_more_slowly() -> None:
    """p = 0.5 (l_q 7/8, l_v 9/16, l_d 1/8): the unknown acceleration's velocity error decays,
    but is not gone at sample 3 as the deadbeat one's is."""
    times = T * np.arange(40)
    v = _estimates(0.5 * A * times ** 2, np.zeros(40), 0.5)
    gains = observer_gains(np.array([0.5]), np.array([True]), T)
    assert gains[:3, 0] * [1.0, T, T * T] == pytest.approx([7 / 8, 9 / 16, 1 / 8])
    error = np.abs(v - A * times)
    assert error[3] > 1e-3 and error[-1] < 1e-6


def test_on_the_joints_the_floors_raised_only() -> None:
    """patient_aware.yaml on the paper's arm: the elbow (K_D floor) and the shoulder flexion
    (K_P floor) get the observer, the shoulder abduction (225 / 30 as given) does not; on the
    UR5 no floor raises a gain, so no joint has it; the shipped config (1.0) has none."""
    paper = load_config(None, overlays=[config_dir() / "patient_aware.yaml"])
    on = velocity_observer_gains(paper)[0] > 0.0
    assert on.tolist() == [True, False, True]
    ur5 = load_config(config_dir() / "arms" / "ur5.yaml",
                      overlays=[config_dir() / "patient_aware.yaml"])
    assert not np.any(velocity_observer_gains(ur5)[0])
    assert not np.any(velocity_observer_gains(load_config(None))[0])
    assert not np.any(velocity_observer_gains(
        paper.replace({"control.velocity_observer": 1.0}))[0])


def test_a_pole_above_one_is_refused_naming_the_key() -> None:
    with pytest.raises(ConfigError, match=r"control\.velocity_observer"):
        load_config(None, overrides={"control.velocity_observer": 1.5})


def test_a_trials_commands_are_formed_again_from_its_samples() -> None:
    """A 14-bit encoder patient with the observer: the commands the graph's supervisor forms
    again from the sampled (measured) states (record_from_samples, the observer run over them)
    are the trial's bit for bit, and the velocity fed back (fed_back_velocity) is u's."""
    config = load_config(None, overlays=[config_dir() / "patient_aware.yaml"]).replace({
        "patient.sensor.quantisation": 2 * np.pi / 2 ** 14,
        "patient.sensor.differentiate_velocity": True,
        "patient.sensor.velocity_filter": 0.01,
        "patient.spasticity.mas_grade": "3", "patient.spasticity.reflex_delay": 0.1})
    experiment = Experiment(config)
    n = experiment.reference.position.shape[1]
    feedforward = np.zeros((experiment.reference.samples, n))
    record = experiment.run_trial(feedforward, 1)
    assert record.aborted_at is None
    again = record_from_samples(experiment, 1, feedforward, record.position, record.velocity)
    assert np.array_equal(again.control_input, record.control_input)
    fed = fed_back_velocity(record.position, record.velocity, record.control_input,
                            experiment.velocity_observer)
    ref = experiment.reference
    u = ref.velocity - fed  # u = u_ff + K_P e + K_D (qdot_d - v_fed), u_ff = 0
    formed = experiment.kp * (ref.position - record.position) + experiment.kd * u
    assert np.allclose(formed, record.control_input, rtol=0.0, atol=1e-9)
    assert not np.array_equal(fed[:, 2], record.velocity[:, 2])  # the elbow's is the observer's
    assert np.array_equal(fed[:, 1], record.velocity[:, 1])  # the abduction's the measured


@pytest.mark.parametrize("person", ["myoelbow.yaml", "myoarm.yaml"])
def test_a_strapped_person_feeds_back_its_measured_velocity(person: str) -> None:
    """On a strapped person (a plant with no sensor model: MuJoCo's true velocity) the floors
    still raise the elbow's and the shoulder flexion's gains, but no joint gets the observer,
    even with control.velocity_observer 0 (patient_aware.yaml): the commands of a trial are
    K_P e + K_D (qdot_d - qdot) of the measured velocity, and fed_back_velocity is it."""
    from exo_ilc_ros.core.loop.gains import feedback_gains
    from exo_ilc_ros.core.person.experiment import StrappedExperiment

    config = load_config(config_dir() / person, overlays=[config_dir() / "patient_aware.yaml"])
    assert config["control.velocity_observer"] == 0.0
    kp, kd = feedback_gains(config)
    raised = (kp > np.asarray(config["control.kp"])) | (kd > np.asarray(config["control.kd"]))
    assert raised.tolist() == [True, False, True]  # the floors do act on the person's arm
    assert not np.any(velocity_observer_gains(config))
    experiment = StrappedExperiment(config.replace({"musculoskeletal.settle_time": 0.2}))
    assert not np.any(experiment.velocity_observer)
    feedforward = np.zeros_like(experiment.reference.position)
    record = experiment.run_trial(feedforward, 1)
    fed = fed_back_velocity(record.position, record.velocity, record.control_input,
                            experiment.velocity_observer)
    assert np.array_equal(fed, record.velocity)
    ref = experiment.reference
    done = record.aborted_at if record.aborted_at is not None else ref.samples
    formed = (experiment.kp * (ref.position - record.position)
              + experiment.kd * (ref.velocity - record.velocity))[:done]
    assert np.allclose(formed, record.control_input[:done], rtol=0.0, atol=1e-9)
