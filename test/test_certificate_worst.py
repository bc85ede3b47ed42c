"""The worst patient of patient_aware.yaml's certificate on the paper's arm (issue 33; seed 0,
patients 0-290 measured, docs/every-patient.md): patient 62, MAS 3 with a 14-bit encoder, ended
0.32 rad off without an aborted trial under K_P 225 / K_D 30 on the elbow. What the certificate
asserts for it, why it failed, and what the gains' floors (control.min_stiffness,
control.min_damping: the elbow at 1600 / 80) changed. Then the worst with the floors, patient
288 (MAS 3, 14-bit encoder: 0.127 rad off at trial 25, the elbow chattering at ~14 Hz), and
what the velocity observer (control.velocity_observer) changed."""

from __future__ import annotations

import numpy as np

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
    return load_config(None, overlays=[config_dir() / "patient_aware.yaml"])


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
