"""A plant that cannot blow up silently (issue 33): a URDF arm whose light last link carries a
joint damping too stiff for explicit RK4 at 1 ms (h b / I ~ 14, over RK4's ~2.785) is integrated
stably with more sub-steps; one too stiff even for those stops the trial with "the plant diverged
at t on joint j" and the cause, in text and JSON, never a traceback or an error-envelope abort.
A learned input held at feedforward_limit is reported at its limit and never exceeds it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from exo_ilc_ros.analysis.loop import format_growth
from exo_ilc_ros.analysis.report import format_long_run
from exo_ilc_ros.core.convergence.growth import fit_growth, held_at_limit
from exo_ilc_ros.core.learning.qfilter import feedforward_limit_of
from exo_ilc_ros.core.loop.divergence import (
    DIVERGED,
    RK4_REAL_STABILITY,
    damping_stiffness,
    first_non_finite,
)
from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.core.programs.metrics import sparc
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.session.summary import RunSummary
from exo_ilc_ros.core.sim.experiment import Experiment

WRIST_DAMPING = 2.0
"""N m s/rad on the wrist roll, whose link has I = 1.4e-4 kg m^2 about its axis: h b / I ~ 14 at
h = 1 ms, over RK4's limit; the plant takes more sub-steps for it (98 per period)."""
DIVERGING_DAMPING = 200.0
"""N m s/rad: needs ~9700 sub-steps per period, over the 64 x 10 the plant takes at most."""


def _joint(name: str, parent: str, child: str, xyz: str, axis: str, effort: float,
           damping: float) -> str:
    return (f'  <joint name="{name}" type="revolute">\n    <parent link="{parent}"/>\n'
            f'    <child link="{child}"/>\n    <origin xyz="{xyz}" rpy="0 0 0"/>\n'
            f'    <axis xyz="{axis}"/>\n    <limit lower="-3.14" upper="3.14" effort="{effort}" '
            f'velocity="10.0"/>\n    <dynamics damping="{damping}" friction="0.0"/>\n'
            '  </joint>\n')


def _link(name: str, mass: float, com_z: float, ixx: float, izz: float) -> str:
    return (f'  <link name="{name}">\n    <inertial>\n      <origin xyz="0 0 {com_z}" '
            f'rpy="0 0 0"/>\n      <mass value="{mass}"/>\n      <inertia ixx="{ixx}" ixy="0" '
            f'ixz="0" iyy="{ixx}" iyz="0" izz="{izz}"/>\n    </inertial>\n  </link>\n')


def _light_wrist_arm(directory: Path, damping: float = WRIST_DAMPING) -> Path:
    """A 3-joint arm (shoulder pitch, elbow pitch, wrist roll) whose wrist link has
    I = 1.4e-4 kg m^2 about its roll axis, with ``damping`` on the wrist; and a config
    applying the URDF's joint dynamics."""
    urdf = ('<?xml version="1.0"?>\n<robot name="light_wrist">\n  <link name="base_link"/>\n'
            + _joint("shoulder", "base_link", "upper_arm", "0 0 0", "1 0 0", 40.0, 0.0)
            + _link("upper_arm", 1.4, -0.17, 0.0164, 0.0014)
            + _joint("elbow", "upper_arm", "forearm", "0 0 -0.369", "1 0 0", 20.0, 0.0)
            + _link("forearm", 1.1, -0.16, 0.012, 0.0007)
            + _joint("wrist_roll", "forearm", "hand", "0 0 -0.36", "0 0 1", 5.0, damping)
            + _link("hand", 0.2, 0.0, 0.0002, 0.00014)
            + "</robot>\n")
    (directory / "light_wrist.urdf").write_text(urdf)
    schedule = {"position": {"threshold_low": 1.5, "threshold_high": 20.0, "level_mid": 0.03,
                             "level_high": 0.9},
                "velocity": {"threshold_low": 0.1, "threshold_high": 0.2, "level_high": 0.01},
                "acceleration": {"threshold_low": 0.1, "level_high": 0.01}}
    params: dict[str, Any] = {
        "model": {"source": "urdf", "urdf": "light_wrist.urdf", "base_link": "base_link",
                  "tip_link": "hand", "urdf_joint_dynamics": "apply"},
        "trajectory": {"start": [0.0, 0.3, 0.0], "goal": [0.5, 1.2, 0.5]},
        "control": {"kp": 16.0, "kd": 8.0}, "safety": {"hold_kp": 225.0, "hold_kd": 30.0},
        "patient": {"joints": "shoulder_flexion: shoulder, elbow_flexion: elbow"}}
    config = directory / "light_wrist.yaml"
    config.write_text(yaml.safe_dump({
        "/**": {"ros__parameters": params},
        "ilc_supervisor": {"ros__parameters": {"law": "linear", "schedule": schedule}}}))
    return config


def _simulate(*args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env.pop("EXO_ILC_TRACEBACK", None)
    return subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", "simulate", *args],
                          text=True, capture_output=True, env=env, timeout=600)


def test_damping_stiffness_by_hand() -> None:
    """h max eig(a^-1 B): a = diag(2, 1.4e-4), B = diag(0, 2), h = 1 ms -> 14.29 on joint 1."""
    stiffness, joint = damping_stiffness(np.diag([2.0, 1.4e-4]), np.array([0.0, 2.0]), 1e-3)
    assert stiffness == pytest.approx(2.0 / 1.4e-4 * 1e-3, rel=1e-12) and joint == 1
    assert stiffness > RK4_REAL_STABILITY
    assert damping_stiffness(np.eye(2), np.zeros(2), 1e-3) == (0.0, -1)


def test_first_non_finite_names_sample_and_the_joint_moving_fastest_before() -> None:
    q = np.zeros((4, 3))
    qd = np.array([[0.0, 0.0, 0.0], [0.1, -5.0, 0.2], [np.nan, np.nan, np.nan], [0, 0, 0]])
    assert first_non_finite(q, qd) == (2, 1)
    assert first_non_finite(q, np.zeros((4, 3))) is None
    qd[0, 2] = np.inf
    assert first_non_finite(q, qd) == (0, 2)


def test_sparc_of_a_diverged_or_short_speed_does_not_raise() -> None:
    assert np.isnan(sparc(np.array([0.0, 1.0, np.nan]), 100.0))
    assert sparc(np.array([0.0, 1.0]), 100.0, cutoff_hz=1e-9) == 0.0


def test_diverged_plant_named_with_joint_time_and_cause(tmp_path: Path) -> None:
    """Text and --json: the divergence is reported (joint wrist_roll, its time, the RK4
    stability cause), not as an error-envelope abort, and no internal error; the session stops
    at once (learning cannot help a plant that diverged: exit 5, with the session's one
    message)."""
    config = _light_wrist_arm(tmp_path, DIVERGING_DAMPING)
    out = tmp_path / "run.json"
    proc = _simulate("--config", str(config), "--trials", "2", "--json", str(out))
    assert "internal error" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode == 5, proc.stderr
    assert "the plant diverged at t = " in proc.stderr
    assert "stopped after an aborted trial: trial 1: the plant diverged at t = 0.020 s on " \
        in proc.stderr
    assert "on joint wrist_roll: explicit-integration stability" in proc.stderr
    assert "ABORTED by the error envelope" not in proc.stderr
    run = json.loads(out.read_text())["runs"][0]
    diverged = run[DIVERGED]
    assert [d["trial"] for d in diverged] == [1]  # the session stopped there
    first = diverged[0]
    assert first["joint_name"] == "wrist_roll" and first["reason"] == DIVERGED
    assert 0.0 < first["time"] < 1.0 and "h*b/I" in first["cause"]
    assert first["message"] in proc.stderr


def test_damped_light_wrist_stays_finite_at_1_ms(tmp_path: Path) -> None:
    """Damping 2 N m s/rad on the 1.4e-4 kg m^2 wrist, integration_step 1 ms: the plant takes
    ceil(0.01 * max eig(a^-1 B) / 1.4) sub-steps (98; the configured 10 diverged) and the trial
    stays finite and completes; the arm without damping keeps its 10."""
    config = load_config(_light_wrist_arm(tmp_path))
    experiment = Experiment(config)
    a = experiment.plant.metric_tensor(experiment.reference.position[0])
    b = np.array([0.0, 0.0, WRIST_DAMPING])
    assert WRIST_DAMPING / a[2, 2] * 1e-3 > RK4_REAL_STABILITY  # unstable at 1 ms as given
    assert experiment.substeps == 98
    record = experiment.run_trial(np.zeros(experiment.reference.position.shape), 1)
    assert np.all(np.isfinite(record.position)) and np.all(np.isfinite(record.velocity))
    assert not record.aborted
    assert damping_stiffness(a, b, experiment.period / experiment.substeps)[0] <= 1.4
    undamped = Experiment(load_config(_light_wrist_arm(tmp_path, 0.0)))
    assert undamped.substeps == 10


def test_held_at_limit_by_hand() -> None:
    """The last trial's max |u_ff| at feedforward_limit (to 1e-9 relative) is at its limit;
    below it, or with no limit (inf, None), it is not."""
    table = np.array([[0.0, 0.0, 0.0], [100.0, 99.0, 5.0], [100.0, 99.9999, 7.0]])
    assert held_at_limit(table, np.array([100.0, 100.0, np.inf])).tolist() == [True, False,
                                                                                 False]
    assert held_at_limit(table, None).tolist() == [False, False, False]


def test_a_learned_input_held_at_its_limit_is_reported_at_its_limit_not_bounded() -> None:
    """12 trials whose max |u_ff| sits at the limit of 100 on joint 1 (rate 0: the fit alone
    would say "bounded") and converges on joint 2."""
    k = np.arange(12, dtype=float)
    table = np.column_stack([np.full(12, 100.0), 5.0 - 4.0 * 0.5 ** k])
    limit = np.array([100.0, 100.0])
    line = format_growth(fit_growth(table), ["a", "b"], held_at_limit(table, limit))
    assert "AT ITS LIMIT on a " in line and "bounded" not in line, line
    assert "a +0.000" in line and "b " in line
    plain = format_growth(fit_growth(table), ["a", "b"], held_at_limit(table, None))
    assert plain.endswith("-> bounded"), plain
    few = format_growth(fit_growth(table[:3]), ["a", "b"], held_at_limit(table[:3], limit))
    assert "too few trials" in few and "AT ITS LIMIT on a" in few


def test_no_learned_input_above_the_limit_with_the_identified_patient() -> None:
    """feedforward_limit 0.5 with the identification on (the inverse with the patient and the
    hand-over are added after the law's clip): every trial's max |u_ff| <= 0.5, and the long-run
    report says AT ITS LIMIT."""
    config = load_config(overrides={"feedforward_limit": [0.5, 0.5, 0.5],
                                    "identification.enabled": True})
    result = run_trials(config, 0.05, 4)
    assert np.max(result.max_abs_feedforward) <= 0.5
    text = format_long_run([RunSummary.from_result(result)], config["joint_names"],
                           limit=feedforward_limit_of(config))
    assert "AT ITS LIMIT" in text and "bounded" not in text, text
