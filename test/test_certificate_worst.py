"""The worst patient of patient_aware.yaml's certificate on the paper's arm (issue 33; seed 0,
patients 0-290 measured, docs/every-patient.md): patient 62, MAS 3 with a 14-bit encoder, ended
0.32 rad off without an aborted trial under K_P 225 / K_D 30 on the elbow. What the certificate
asserts for it, why it failed, and what the gains' floors (control.min_stiffness,
control.min_damping: the elbow at 1600 / 80) changed. Then the worst with the floors, patient
288 (MAS 3, 14-bit encoder: 0.127 rad off at trial 25, the elbow chattering at ~14 Hz), and
what the velocity observer (control.velocity_observer) changed."""

from __future__ import annotations

import numpy as np
import pytest

from exo_ilc_ros.core.loop.gains import feedback_gains
from exo_ilc_ros.core.loop.rate import with_control_rate
from exo_ilc_ros.core.params.config import Config, config_dir, load_config
from exo_ilc_ros.core.population.certificate import (
    feedforward_limit,
    patient_cell,
    patient_config,
    patient_outcome,
)
from exo_ilc_ros.core.population.distributions import PopulationSpec, draw_patient
from exo_ilc_ros.core.programs.study import run_cell
from exo_ilc_ros.core.session.learning_session import TrialConclusion, run_trials

WORST = 62
"""Seed 0's patient 62: MAS 3, K 2.31 / 3.53 / 2.73 N m/rad, rest 0.27 / 0.59 / 0.23 rad off
the start, 14-bit encoder, mass -9.1 %."""


def _base() -> Config:
    """patient_aware.yaml at 100 Hz (``control.period_rule: fixed``), where these patients were
    measured: the floors, the observer and the certificate's first 1000 of seed 0."""
    return load_config(None, {"control.period_rule": "fixed"},
                       overlays=[config_dir() / "patient_aware.yaml"])


def _shipped() -> Config:
    """patient_aware.yaml as every program runs it: its period_rule gives the paper arm 5 ms."""
    return with_control_rate(load_config(None, overlays=[config_dir() / "patient_aware.yaml"]))


def test_the_worst_patient_is_the_one_the_certificate_names() -> None:
    patient = draw_patient(_base(), PopulationSpec(), 0, WORST)
    assert patient.mas_grade == "3" and patient.overrides["patient.sensor.quantisation"] > 0
    assert np.allclose(patient.overrides["patient.passive.stiffness"], [2.31, 3.53, 2.73],
                       atol=0.005)


def test_the_worst_patient_meets_the_certificate() -> None:
    """The certificate's per-patient criteria over 25 trials: finite, bounded, no more than 2
    aborted trials and none 3 in a row, within 0.005 rad by trial 25 (measured: first within
    at trial 8, settled from 16: not by trial 10, which the certificate asks of 95 % of the
    population, not of each patient)."""
    base = _base()
    patient = draw_patient(base, PopulationSpec(), 0, WORST)
    config = patient_config(base, patient, 25)
    result = run_cell(patient_cell("patient_aware", config, patient))
    outcome = patient_outcome(WORST, result, 25, feedforward_limit(config.values))
    assert outcome.finite and outcome.bounded
    assert outcome.aborts <= 2 and outcome.abort_run < 3
    assert outcome.passes and outcome.within_by(25), outcome.worst_error_per_trial


def _elbow_chatter(record) -> float:
    """RMS of the elbow's true error about its 25-sample moving mean (rad): the ~5 Hz limit
    cycle of a delayed reflex, not the slow error learning removes."""
    true = record.position if record.true_position is None else record.true_position
    error = record.reference.position[:, 2] - true[:, 2]
    wiggle = error - np.convolve(error, np.ones(25) / 25.0, mode="same")
    return float(np.sqrt(np.mean(wiggle[25:-25] ** 2)))


def test_why_the_worst_patient_failed_without_the_floors() -> None:
    """Four trials under the gains before the floors (K_P 225 / K_D 30 on the elbow): the
    elbow (joint index 2) chatters (0.01-0.07 rad about its mean: MAS 3's delayed stretch
    reflex in the loop), every trial is refused whole ("moved faster than the regression
    resolves") and no identified force is ever used; the elbow stays 0.2-0.4 rad off."""
    base = _base().replace({"control.min_stiffness": 0.0, "control.min_damping": 0.0})
    patient = draw_patient(base, PopulationSpec(), 0, WORST)
    config = patient_config(base, patient, 4)
    seen: list[TrialConclusion] = []
    result = run_trials(config, on_conclusion=seen.append)
    for conclusion in seen:
        forces = conclusion.joint_forces
        assert forces is not None and not np.any(forces.used)
        assert "joint 2 moved faster than the regression resolves" in \
            forces.estimate.rejected, forces.estimate.rejected
    elbow = [float(np.max(np.abs(r.error[:, 2]))) for r in result.records]
    assert all(0.2 < e < 0.4 for e in elbow), elbow
    assert all(_elbow_chatter(r) > 0.01 for r in result.records)


def test_the_floors_damp_the_elbows_chatter() -> None:
    """The floors (the elbow at K_P 1600 / K_D 80): the chatter is there in
    trial 1 (the learned input is still zero) and gone by trial 4 (measured 0.0007 rad about
    the mean, elbow 0.015 rad off; 0.04 and 0.33 rad under the old gains). The floors alone:
    the measured velocity fed back, as before the velocity observer (with it, 0.0038 rad about
    the mean at trial 4 and settled from trial 6, not 16)."""
    base = _base().replace({"control.velocity_observer": 1.0})
    patient = draw_patient(base, PopulationSpec(), 0, WORST)
    result = run_trials(patient_config(base, patient, 4))
    assert _elbow_chatter(result.records[-1]) < 0.003
    assert float(np.max(np.abs(result.records[-1].error[:, 2]))) < 0.05


WORST_WITH_FLOORS = 288
"""Seed 0's patient 288: MAS 3, K 2.97 / 2.57 / 3.23 N m/rad, rest -0.44 / -0.41 / 0.03 rad,
14-bit encoder, mass +5.3 %: the worst of the first 311 with the floors (0.127 rad off at
trial 25, never within)."""


def test_the_worst_patient_with_the_floors_meets_the_certificate() -> None:
    """With the velocity observer on the floors' joints (patient_aware.yaml's
    ``control.velocity_observer: 0``): the certificate's per-patient criteria over 25 trials,
    and within the bound by trial 10 (measured: settled from trial 7, 2.6e-3 rad at 25)."""
    base = _base()
    patient = draw_patient(base, PopulationSpec(), 0, WORST_WITH_FLOORS)
    assert patient.mas_grade == "3" and patient.overrides["patient.sensor.quantisation"] > 0
    config = patient_config(base, patient, 25)
    result = run_cell(patient_cell("patient_aware", config, patient))
    outcome = patient_outcome(WORST_WITH_FLOORS, result, 25, feedforward_limit(config.values))
    assert outcome.finite and outcome.bounded
    assert outcome.aborts == 0
    assert outcome.passes and outcome.within_by(10), outcome.worst_error_per_trial


def test_without_the_observer_the_encoders_velocity_keeps_the_elbow_chattering() -> None:
    """The same patient with the measured (differenced, 10 ms low-passed) velocity fed back,
    as before the observer: the elbow chatters at ~14 Hz in trial 4 and is more than 0.05 rad
    off (measured 0.115); with the observer the chatter is below 0.003 rad by trial 4."""
    base = _base()
    patient = draw_patient(base, PopulationSpec(), 0, WORST_WITH_FLOORS)
    before = run_trials(patient_config(base, patient, 4, {"control.velocity_observer": 1.0}))
    last = before.records[-1]
    true = last.true_position
    error = last.reference.position[:, 2] - true[:, 2]
    wiggle = (error - np.convolve(error, np.ones(25) / 25.0, mode="same"))[25:-25]
    frequency = np.fft.rfftfreq(wiggle.size, last.reference.period)
    peak = frequency[1 + int(np.argmax(np.abs(np.fft.rfft(wiggle))[1:]))]
    assert 12.0 < peak < 16.0, peak
    assert _elbow_chatter(last) > 0.01
    assert float(np.max(np.abs(error))) > 0.05
    after = run_trials(patient_config(base, patient, 4))
    assert _elbow_chatter(after.records[-1]) < 0.003


LEFT_WITH_THE_OBSERVER = 464
"""Seed 0's patient 464: MAS 3, K 2.27 / 2.97 / 3.71 N m/rad, viscous 0.05 / 0.26 / 0.02 N m
s/rad (the elbow's the lowest of the eight MAS 3 encoder patients), 14-bit encoder, mass
-8.5 %: the one patient of seed 0's first 1000 the observer left (0.0111 rad at trial 25,
never within)."""


def _elbow_fast_velocity(record) -> np.ndarray:
    """RMS of the elbow's true velocity in the 18-48 Hz band over each 0.5 s of the trial
    (rad/s): the delayed reflex's fast mode, not the movement."""
    from scipy.signal import butter, sosfiltfilt
    band = butter(4, [18.0, 48.0], btype="band", fs=1.0 / record.reference.period,
                  output="sos")
    fast = sosfiltfilt(band, record.true_velocity[:, 2])
    window = int(round(0.5 / record.reference.period))
    return np.array([np.std(fast[s:s + window]) for s in range(0, fast.size - 1, window)])


def test_the_reflex_outruns_any_velocity_feedback_at_100_hz() -> None:
    """Hand-computed: a joint with the best velocity feedback there is at period T (deadbeat,
    K_D T = 1, K_P 0, no patient) and a reflex G / I on the velocity d periods ago has
    v_{i+1} = -(G T / I) v_{i-d}, poles of radius (G T / I)^(1 / (d + 1)) (and the position's
    at 1): MAS 3's G 2 N m s/rad on patient 464's elbow in its last second (I 0.0136 kg m^2),
    d 10 at 100 Hz, G T / I = 1.47: radius 1.47^(1/11) = 1.0357, unstable whatever the
    gains; at 200 Hz (d 20) G T / I = 0.735 < 1."""
    from exo_ilc_ros.core.convergence.joint_loop import JointLoop
    radii = []
    for period, delay in ((0.01, 10), (0.005, 20)):
        b = 2.0 * period / 0.0136
        loop = JointLoop(1.0, 0.0, 1.0 / period, period, reflex=2.0 / 0.0136,
                         reflex_delay=delay)
        radii.append(loop.spectral_radius()[0])
        assert radii[-1] == pytest.approx(max(1.0, b ** (1.0 / (delay + 1))), rel=1e-9)
    assert radii == [pytest.approx(1.0357, abs=1e-4), pytest.approx(1.0, rel=1e-9)]
    # the loop with the patient's elbow in it (K 3.71 + 8, B 0.02 + 0.8, mass -8.5 %): at
    # 100 Hz every PD of the grid keeps a pole outside the unit circle; at 200 Hz the floors'
    # K_P with K_D 137 (min_damping 1.5 over 0.011) has none at any inertia along the movement
    for kp in (225.0, 900.0, 1600.0, 3600.0):
        for kd in (30.0, 60.0, 80.0, 100.0, 150.0):
            loop = JointLoop(1.0 / 0.915, kp, kd, 0.01, 11.71 / 0.0136, 0.82 / 0.0136,
                             2.0 / 0.0136, 10, continuous_patient=True)
            assert loop.spectral_radius()[0] > 1.0, (kp, kd)
    for inertia in (0.011, 0.0136, 0.0148, 0.02, 0.041):
        loop = JointLoop(1.0 / 0.915, 1649.0, 137.0, 0.005, 11.71 / inertia, 0.82 / inertia,
                         2.0 / inertia, 20, continuous_patient=True)
        assert loop.spectral_radius()[0] < 1.0, inertia


@pytest.mark.xfail(strict=True, reason="patient 464 at 100 Hz: the elbow's delayed-reflex "
                   "mode no PD can hold (docs/every-patient.md); strict, so a fix shows")
def test_the_patient_the_observer_left_meets_the_certificate() -> None:
    """The certificate's per-patient criteria for 464 under patient_aware.yaml at 100 Hz, as
    it was shipped before its period_rule (measured: 0.0111 rad at trial 25, never within:
    trials 12-23 0.035-0.086 rad)."""
    base = _base()
    patient = draw_patient(base, PopulationSpec(), 0, LEFT_WITH_THE_OBSERVER)
    config = patient_config(base, patient, 25)
    result = run_cell(patient_cell("patient_aware", config, patient))
    outcome = patient_outcome(LEFT_WITH_THE_OBSERVER, result, 25,
                              feedforward_limit(config.values))
    assert outcome.passes and outcome.within_by(25), outcome.worst_error_per_trial


def test_why_the_patient_the_observer_left_fails() -> None:
    """Trial 12 of 464 (the law at 100 Hz): the elbow's true velocity swings at ~32 Hz with more
    than 1 rad/s RMS in the trial's last second (the delayed reflex's mode, grown into the
    reflex's ceiling; measured 3.4 and 4.2), though the reference moves it at 0.2 rad/s at most,
    and the trial ends more than 0.03 rad off (0.067); no identified force is used in any
    trial (every one refused as chatter)."""
    base = _base()
    patient = draw_patient(base, PopulationSpec(), 0, LEFT_WITH_THE_OBSERVER)
    seen: list[TrialConclusion] = []
    result = run_trials(patient_config(base, patient, 12), on_conclusion=seen.append)
    last = result.records[-1]
    assert np.all(_elbow_fast_velocity(last)[-2:] > 1.0), _elbow_fast_velocity(last)
    velocity = last.true_velocity[:, 2]
    window = velocity[400:] - np.mean(velocity[400:])
    frequency = np.fft.rfftfreq(window.size, last.reference.period)
    peak = frequency[1 + int(np.argmax(np.abs(np.fft.rfft(window))[1:]))]
    assert 28.0 < peak < 36.0, peak
    assert float(np.max(np.abs(last.error))) > 0.03
    assert all(c.joint_forces is None or not np.any(c.joint_forces.used) for c in seen)


def test_the_patient_the_observer_left_meets_the_certificate_at_200_hz() -> None:
    """The shipped law: its ``control.period_rule: reflex`` runs the paper arm at 200 Hz (5 ms,
    the floors and the observer at that period: the elbow K_P 1649 / K_D 137, min_damping 1.5
    over its 0.011 kg m^2), where the delayed reflex no longer outruns the feedback
    (G T / I < 1), and 464 meets the certificate's per-patient criteria, within the bound by
    trial 10 (measured: settled from trial 5, 8.5e-4 rad at 25)."""
    base = _shipped()
    assert base["control.period"] == 0.005
    kp, kd = feedback_gains(base)
    assert kp[2] == pytest.approx(18.0 / 0.01091, rel=2e-3)
    assert kd[2] == pytest.approx(1.5 / 0.01091, rel=2e-3)
    patient = draw_patient(base, PopulationSpec(), 0, LEFT_WITH_THE_OBSERVER)
    config = patient_config(base, patient, 25)
    result = run_cell(patient_cell("patient_aware", config, patient))
    outcome = patient_outcome(LEFT_WITH_THE_OBSERVER, result, 25,
                              feedforward_limit(config.values))
    assert outcome.finite and outcome.bounded and outcome.aborts == 0
    assert outcome.passes and outcome.within_by(10), outcome.worst_error_per_trial
