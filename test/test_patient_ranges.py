"""The trial-to-trial factor with the patient in the loop over ranges of patients
(core/convergence/patient_ranges.py, ``exo-ilc analyze-loop --patient-ranges``), and the
shipped law config/patient_aware.yaml on hard patients of the other arms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.convergence.joint_loop import JointLoop
from exo_ilc_ros.core.convergence.patient_ranges import (
    PatientRanges,
    analyze_patient_ranges,
    factor_with_patient,
    lightest_inverse_inertia,
)
from exo_ilc_ros.core.learning.laws import Memory
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import config_dir

ROOT = Path(__file__).resolve().parents[1]
AWARE = config_dir() / "patient_aware.yaml"
ARMS = [None, ROOT / "config" / "arms" / "panda.yaml", ROOT / "config" / "arms" / "ur5.yaml"]


def _one_joint(**overrides: object):
    """The paper's forearm alone: one joint, every per-joint key its elbow's value (one value
    for every joint), the patient's elbow on it."""
    base = load_config()
    values: dict[str, object] = {p.name: base[p.name][-1] for p in schema.PARAMETERS
                                 if p.per_joint and p.name not in ("model.joint_axes",)}
    values.update({"joint_names": ["elbow_flexion"], "model.joint_axes": ["y"],
                   "trajectory.start": [0.0], "trajectory.goal": [1.0],
                   "q_filter.enabled": False, "progress_gain.position": 0.0,
                   "averaging.memory": 0.0, "law": "linear", "memory": "total_input",
                   "linear.gain_position": 0.0, "linear.gain_velocity": 0.0,
                   "linear.gain_acceleration": 1.0, **overrides})
    return base.replace(values)


def test_one_joint_factor_adds_k_over_i_by_hand() -> None:
    """One joint of inertia I under K_P, K_D: a patient's K adds K / I to the loop's
    stiffness. At 0 Hz the plant is static, q = u_ff / (K_P + K / I), so the memory's input
    sensitivity is S = 1 - K_P / (K_P + K / I) and e_ddot's term vanishes: F(0) = (K / I) /
    (K_P + K / I), with the progress gain G: (K / I - G) / (K_P + K / I)."""
    config = _one_joint()
    inertia = float(build_arm(config).metric_tensor([0.3])[0, 0])  # one joint: a constant
    assert lightest_inverse_inertia(config)[0] == pytest.approx(1.0 / inertia)
    kp, kd, k = 10.0, 7.0, 4.0
    s = k / inertia
    loop = JointLoop(1.0 / 1.1, kp, kd, 0.01, s, 0.0)
    zero = np.array([0.0])
    one = np.ones(1)
    assert factor_with_patient(loop, zero, Memory.TOTAL_INPUT, (0.0, 0.0, 1.0), 0.0, (1.0,),
                               one)[0] == pytest.approx(s / (kp + s))
    assert factor_with_patient(loop, zero, Memory.TOTAL_INPUT, (0.0, 0.0, 1.0), 5.0, (1.0,),
                               one)[0] == pytest.approx(max(s / (kp + s),
                                                            abs(s - 5.0) / (kp + s)))
    # averaging: u_ff,k+1 = (1 - K) u_ff,k + K F u_ff,k, the worst of K = 0.7 and 1
    assert factor_with_patient(loop, zero, Memory.TOTAL_INPUT, (0.0, 0.0, 1.0), 0.0,
                               (0.7, 1.0), one)[0] == pytest.approx(0.3 + 0.7 * s / (kp + s))
    # the range analysis over K in {0, 4}: its worst is the K = 4 corner's, over frequency
    ranges = PatientRanges(stiffness=k, viscous=0.0, mas_grades=("0",),
                           mass_uncertainty=(0.1,))
    worst = analyze_patient_ranges(config, ranges).joints[0]
    frequency = np.linspace(0.0, 50.0, 1001)
    expected = factor_with_patient(loop, frequency, Memory.TOTAL_INPUT, (0.0, 0.0, 1.0), 0.0,
                                   (1.0,), np.ones_like(frequency))
    assert worst.worst == pytest.approx(float(np.max(expected)))
    # a forearm this stiff (K / I ~ 97 s^-2 against K_P 10) makes the paper's law grow at
    # ~1.4 Hz, where without a patient only the Nyquist peak (1.03, Q-filter off) exceeds 1
    assert worst.stiffness == k and worst.worst > 1.4 and 0.5 < worst.frequency_hz < 3.0
    nominal = JointLoop(1.0 / 1.1, kp, kd, 0.01).factor(frequency, Memory.TOTAL_INPUT,
                                                        (0.0, 0.0, 1.0))
    assert worst.nominal == pytest.approx(float(np.max(nominal)))


@pytest.mark.parametrize("arm", ARMS, ids=lambda a: "paper" if a is None else a.stem)
def test_the_shipped_law_contracts_for_every_patient_in_the_ranges(arm: Path | None) -> None:
    """patient_aware.yaml's factor with the patient in the loop stays below 1 at every corner
    of the ranges on every shipped arm; the paper's PD gains under the same law do not on the
    paper arm's light elbow (the check can fail)."""
    config = load_config(arm, overlays=[AWARE])
    assert analyze_patient_ranges(config).worst() < 0.9
    if arm is None:
        paper = config.replace({"control.kp": [16.0, 10.0, 10.0],
                                "control.kd": [8.0, 5.0, 7.0]})
        assert analyze_patient_ranges(paper).worst() > 1.0


def test_analyze_loop_prints_the_factor_with_the_patient(capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    assert main(["analyze-loop", "--config", str(AWARE), "--patient-ranges",
                 "--range-mas", "2"]) == 0
    out = capsys.readouterr().out
    assert "with the patient in the loop, worst over passive stiffness 0-4 N m/rad" in out
    assert "MAS 0, 1, 1+, 2, mass error" in out
    assert "learning converges for every patient in the ranges" in out


HARD = {
    "stiff": {"patient.passive.stiffness": [2.0, 2.0, 1.0],
              "patient.passive.rest_position": [-0.4, -0.4, -0.3]},
    "mas3": {"patient.spasticity.mas_grade": "3", "patient.spasticity.reflex_delay": 0.1,
             "patient.passive.stiffness": 4.0, "patient.passive.rest_position": [0.6, -0.6, 0.6]},
    "friction": {"patient.friction.viscous": 0.4, "patient.friction.coulomb": 0.35,
                 "patient.sensor.quantisation": 2.0 * np.pi / 2 ** 14},
}


@pytest.mark.parametrize("arm", ARMS[1:], ids=lambda a: a.stem)
@pytest.mark.parametrize("patient", list(HARD))
def test_hard_patients_on_other_arms_within_the_bound(arm: Path, patient: str) -> None:
    """The stiff patient that makes robust.yaml abort, a spastic MAS 3 and a friction-heavy
    one with a 14-bit encoder, at 15 % mass error: within 0.005 rad by trial 25 (measured: first
    within at trials 3-11, the Panda's MAS 3 the last: its wrist, driven through a_N^-1), no
    abort (~3-5 s each)."""
    config = load_config(arm, overlays=[AWARE]).replace(HARD[patient])
    result = run_trials(config, mass_uncertainty=0.15, trials=25)
    assert not result.aborted
    assert np.all(result.true_max_abs_errors()[-1] <= 0.005)
