"""The convergence analysis against a patient's arm (core/convergence/patient_load.py, the
patient in JointLoop and in norm-optimal's robustness check, ``exo-ilc analyze-loop
--scenarios``)."""

from __future__ import annotations

import numpy as np
import pytest

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.convergence.factors import analyze_loop
from exo_ilc_ros.core.convergence.joint_loop import JointLoop
from exo_ilc_ros.core.convergence.patient_load import patient_load
from exo_ilc_ros.core.params.config import config_dir, load_config, scenario_path


def test_the_patients_forces_add_to_the_pd_in_the_loop() -> None:
    """qdd = g (u - s q - d qdot): the loop with the patient's s, d equals the loop whose PD
    gains are K_P + s, K_D + d (its transfer functions), while the input sensitivity keeps the
    controller's own gains."""
    z = np.exp(2j * np.pi * np.linspace(0.01, 49.0, 50) * 0.01)
    with_patient = JointLoop(0.9, 10.0, 7.0, 0.01, 20.0, 3.0)
    shifted = JointLoop(0.9, 30.0, 10.0, 0.01)
    for a, b in zip(with_patient.closed_loop(z), shifted.closed_loop(z), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13)
    pq, pv = with_patient.closed_loop(z)
    np.testing.assert_allclose(with_patient.sensitivity(z), 1.0 - 10.0 * pq - 7.0 * pv)


def test_patient_load_by_hand() -> None:
    """spastic: its MAS 2 preset (4 N m/rad, 0.4 N m s/rad) added to the scenario's passive
    stiffness and viscous friction, and the same per unit of the joint's nominal inertia at the
    reference's start."""
    config = load_config(overlays=[scenario_path("spastic")])
    load = patient_load(config, "spastic")
    stiffness = np.add(config["patient.passive.stiffness"], 4.0)
    damping = np.add(config["patient.friction.viscous"], 0.4)
    np.testing.assert_allclose(load.torque_stiffness, stiffness)
    np.testing.assert_allclose(load.torque_damping, damping)
    inertia = np.diag(build_arm(config).metric_tensor(np.asarray(config["trajectory.start"])))
    np.testing.assert_allclose(load.stiffness, stiffness / inertia)


def test_identified_patient_makes_the_update_fast_where_it_was_slow() -> None:
    """robust.yaml against the spastic arm: its worst factor is near 1 (77 trials to the bound
    in the study); patient_aware.yaml, whose update inverts the identified forces, brings it
    to about the arm alone's."""
    spastic = patient_load(load_config(overlays=[scenario_path("spastic")]), "spastic")
    robust = load_config(config_dir() / "robust.yaml")
    aware = load_config(config_dir() / "patient_aware.yaml")
    alone = analyze_loop(robust.with_mass_uncertainty(0.1)).worst(filtered=True)
    slow = analyze_loop(robust.with_mass_uncertainty(0.1), patient=spastic).worst(filtered=True)
    fast = analyze_loop(aware.with_mass_uncertainty(0.1), patient=spastic).worst(filtered=True)
    assert slow > 0.85 and fast < 0.2 and fast < alone + 0.01


def test_analyze_loop_names_the_patients(capsys: pytest.CaptureFixture[str]) -> None:
    """``exo-ilc analyze-loop --scenarios`` prints one line per patient and delta and which
    patients the learning stays bounded for."""
    assert main(["analyze-loop", "--config", str(config_dir() / "patient_aware.yaml"),
                 "--scenarios", "friction", "spastic"]) == 0
    out = capsys.readouterr().out
    assert "the update inverting them" in out
    assert "  friction " in out and "  spastic " in out
    assert "bounded for: friction, spastic; can grow for: none" in out
