"""The feedback gains' absolute floors (core/loop/gains.py, control.min_stiffness and
control.min_damping): K_P,j >= k_min / I_j and K_D,j >= d_min / I_j on the joints a patient
acts on, I_j the lightest inertia along the reference, and on the others by the coupling of the
patient's torques into them, capped at K_D T = 0.8 (issue 33: MAS 3's delayed stretch reflex on
the paper arm's light elbow; the light hand of a human arm beyond the patient's elbow)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core import load_config
from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.loop.gains import feedback_gains, gain_caps
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import config_dir
from exo_ilc_ros.core.reference.build import build_reference
from exo_ilc_ros.core.sim.experiment import Experiment

ROOT = Path(__file__).resolve().parents[1]
AWARE = config_dir() / "patient_aware.yaml"


def _one_joint(**overrides: object):
    """The paper's forearm alone (one joint: its inertia is the same at every angle)."""
    base = load_config()
    values: dict[str, object] = {p.name: base[p.name][-1] for p in schema.PARAMETERS
                                 if p.per_joint and p.name not in ("model.joint_axes",)}
    values.update({"joint_names": ["elbow_flexion"], "model.joint_axes": ["y"],
                   "trajectory.start": [0.0], "trajectory.goal": [1.0], **overrides})
    return base.replace(values)


def test_floors_by_hand_on_one_joint() -> None:
    """One joint of inertia I (a_N's only entry): K_P = max(kp, k_min / I), K_D = max(kd,
    d_min / I), each floor capped at (0.8 / T)^2 / 4 and 0.8 / T; a kp above the cap is the
    config's own and kept; zero floors give the config's gains exactly."""
    inertia = float(build_arm(_one_joint()).metric_tensor([0.4])[0, 0])
    assert 0.01 < inertia < 0.1
    config = _one_joint(**{"control.kp": 10.0, "control.kd": 7.0,
                           "control.min_stiffness": 0.5, "control.min_damping": 0.2})
    kp, kd = feedback_gains(config)
    assert kp[0] == pytest.approx(max(10.0, 0.5 / inertia))
    assert kd[0] == pytest.approx(max(7.0, 0.2 / inertia))
    assert gain_caps(0.01) == pytest.approx((1600.0, 80.0))
    capped = config.replace({"control.min_stiffness": 1e4, "control.min_damping": 1e3})
    assert np.allclose(feedback_gains(capped), ([1600.0], [80.0]))
    own = capped.replace({"control.kp": 5000.0, "control.kd": 120.0})
    assert np.allclose(feedback_gains(own), ([5000.0], [120.0]))
    plain = _one_joint(**{"control.kp": 10.0, "control.kd": 7.0})
    kp, kd = feedback_gains(plain)
    assert kp.tolist() == [10.0] and kd.tolist() == [7.0]


def test_patient_joints_by_their_inertia_the_others_by_the_coupling() -> None:
    """On the Panda (patient on joints 2, 1 and 4) a patient's joint's floor scales with its
    own lightest inverse inertia, max_t (a_N^-1)_jj, and every other joint's with the largest
    acceleration a patient's torque gives it, max_t max_j |(a_N^-1)_kj| over the patient's
    joints j (a_N computed here from the arm and the reference); the controller of the
    in-process loop runs the raised gains. A config without floors keeps its digest (the keys
    are left out of the identity at 0: stores made before them still match)."""
    panda = load_config(ROOT / "config" / "arms" / "panda.yaml", overlays=[AWARE])
    raised = panda.replace({"control.min_stiffness": 60.0, "control.min_damping": 10.0})
    kp, kd = feedback_gains(raised)
    inverse = np.linalg.inv(build_arm(raised).metric_tensors(
        build_reference(raised).position))
    on, off = [1, 0, 3], [2, 4, 5, 6]
    own = np.max(np.diagonal(inverse, axis1=1, axis2=2), axis=0)
    coupled = np.max(np.abs(inverse[:, :, on]), axis=(0, 2))
    for joints, scale in ((on, own), (off, coupled)):
        np.testing.assert_allclose(kp[joints], np.maximum(225.0, np.minimum(
            60.0 * scale[joints], 1600.0)), rtol=1e-12)
        np.testing.assert_allclose(kd[joints], np.maximum(30.0, np.minimum(
            10.0 * scale[joints], 80.0)), rtol=1e-12)
    assert np.any(kp[off] > 225.0) and np.any(kp[off] == 225.0)  # the coupling decides
    assert np.all(own[4:] > coupled[4:])  # the wrist's own inertia would raise it more
    experiment = Experiment(raised)
    assert np.array_equal(experiment.kp, kp) and np.array_equal(experiment.kd, kd)
    floorless = panda.replace({"control.min_stiffness": 0.0, "control.min_damping": 0.0})
    assert "control.min_damping" not in floorless.identity_values()
    assert "control.min_damping" in raised.identity_values()


def test_patient_aware_raises_the_paper_elbow_only_where_light() -> None:
    """patient_aware.yaml's floors: on the paper arm the elbow (I 0.0109 kg m^2) runs the
    caps, K_P 1600 s^-2 and K_D 80 s^-1 (1600 x 0.0109 = 17.5 N m/rad and 0.87 N m s/rad, where
    K_P 225 / K_D 30 were 2.5 and 0.33); on the UR5 and the Panda, whose patient joints weigh
    0.1 kg m^2 and more, the gains stay 225 / 30."""
    paper = load_config(None, overlays=[AWARE])
    kp, kd = feedback_gains(paper)
    assert kp[2] == pytest.approx(1600.0) and kd[2] == pytest.approx(80.0)
    assert kd[0] == kd[1] == 30.0 and kp[1] == 225.0
    for arm in ("ur5", "panda"):
        config = load_config(ROOT / "config" / "arms" / f"{arm}.yaml", overlays=[AWARE])
        kp, kd = feedback_gains(config)
        assert np.all(kp == 225.0) and np.all(kd == 30.0)
