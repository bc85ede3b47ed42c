"""The worst patient of patient_aware.yaml's certificate on the paper's arm (issue 33; seed 0,
patients 0-290 measured, docs/every-patient.md): patient 62, MAS 3 with a 14-bit encoder, ends
0.32 rad off without an aborted trial. What the certificate asserts for it, and why it fails."""

from __future__ import annotations

import numpy as np
import pytest

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


@pytest.mark.xfail(strict=True, reason="issue 33, open: on the paper arm patient_aware.yaml "
                   "leaves MAS 3 patients 0.2-0.3 rad off (10 of 15 in seed 0's first 291); "
                   "the identification refuses every trial for the elbow's chatter")
def test_the_worst_patient_meets_the_certificate() -> None:
    """The certificate's per-patient criteria over 25 trials: finite, bounded, no more than 2
    aborted trials and none 3 in a row, within 0.005 rad by trial 25 (and by 10)."""
    base = _base()
    patient = draw_patient(base, PopulationSpec(), 0, WORST)
    config = patient_config(base, patient, 25)
    result = run_cell(patient_cell("patient_aware", config, patient))
    outcome = patient_outcome(WORST, result, 25, feedforward_limit(config.values))
    assert outcome.finite and outcome.bounded
    assert outcome.aborts <= 2 and outcome.abort_run < 3
    assert outcome.within_by(10), outcome.worst_error_per_trial


def test_why_the_worst_patient_fails_the_identification_refuses_every_trial() -> None:
    """Four trials: the elbow (joint index 2) moves above the regression's 10 Hz cut-off (0.01-
    0.05 rad RMS: chatter, with MAS 3's delayed stretch reflex in the stiff loop), so every
    trial is refused whole and no identified force is ever used; the elbow stays 0.27-0.35 rad
    off (the refusal is one reason: with it relaxed the elbow still ends 0.31 rad off at trial
    12). When the law learns this patient, this test says which rule changed."""
    base = _base()
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
