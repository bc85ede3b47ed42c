"""The musculoskeletal person's neural drive (core/person/neural_drive.py): the reflex law by
hand, the compiled step against it (delay, tone, spastic muscles only, ceiling, fatigue,
voluntary activation), the config's keys and the MAS presets' rule."""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.core.person.neural_drive import (
    MAS_DRIVE_PRESETS,
    DriveSettings,
    NeuralDrive,
    drive_settings,
    reflex_excitation,
    steps_of,
)

pytest.importorskip("myo_sim")
FLEXORS = ("BIClong", "BICshort", "BRA", "BRD")


@pytest.fixture(scope="module")
def elbow() -> object:
    from exo_ilc_ros.core.person.model import person_spec
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return person_spec("myoelbow").compile()


def test_reflex_law_by_hand() -> None:
    """r = min(R, max(0, L - L_th) (g_l + g_v max(0, V - V_th))), computed by hand."""
    s = DriveSettings(length_threshold=1.0, velocity_threshold=0.2, length_gain=0.5,
                      velocity_gain=2.0, reflex_max=0.3)
    length = np.array([1.1, 0.9, 1.2, 2.0, 1.0])
    velocity = np.array([0.5, 5.0, 0.1, 1.0, 3.0])
    expected = [0.1 * (0.5 + 2.0 * 0.3),  # both above: 0.11
                0.0,                      # shorter than L_th: nothing, however fast
                0.2 * 0.5,                # slower than V_th: the static term only, 0.1
                0.3,                      # 1.0 * (0.5 + 1.6) = 2.1, clipped at R
                0.0]                      # exactly at L_th
    np.testing.assert_allclose(reflex_excitation(length, velocity, s), expected, atol=1e-15)


def test_delay_steps_round_half_up() -> None:
    assert steps_of(0.1, 0.002) == 50
    assert steps_of(0.003, 0.002) == 2
    assert steps_of(0.0, 0.002) == 0


def fake_data(model: object) -> SimpleNamespace:
    nu = model.nu  # type: ignore[attr-defined]
    return SimpleNamespace(actuator_length=np.zeros(nu), actuator_velocity=np.zeros(nu),
                           ctrl=np.zeros(nu))


def set_normalised(drive: NeuralDrive, data: SimpleNamespace, name: str, length: float,
                   velocity: float) -> None:
    """Put muscle ``name`` at a normalised fibre length and velocity (inverting MuJoCo's
    normalisation the drive reads)."""
    g = drive.geometry
    i = g.names.index(name)
    data.actuator_length[g.actuators[i]] = (length - g.offset[i]) / g.scale[i]
    data.actuator_velocity[g.actuators[i]] = velocity / g.scale[i]


def test_step_is_the_law_delayed_on_spastic_muscles_only(elbow: object) -> None:
    """A stretch of every muscle at step 10: ctrl stays the tone until step 10 + D, then is
    tone + the law of the stretched state on the spastic muscles, the tone elsewhere."""
    s = DriveSettings(tone=0.02, length_threshold=1.0, velocity_threshold=0.1,
                      length_gain=0.3, velocity_gain=0.5, reflex_max=0.5, delay=0.01,
                      spastic_muscles=("BIClong", "BRA"))
    drive = NeuralDrive(elbow, s)
    assert drive.delay_steps == 5  # 0.01 s at MuJoCo's 2 ms
    data = fake_data(elbow)
    names = drive.geometry.names
    for name in names:
        set_normalised(drive, data, name, 0.8, 0.0)
    ctrl = []
    for k in range(20):
        if k == 10:
            for name in names:
                set_normalised(drive, data, name, 1.2, 0.6)
        drive.step(data)
        ctrl.append(data.ctrl[drive.geometry.actuators].copy())
    reflex = 0.2 * (0.3 + 0.5 * 0.5)  # 0.11, below the ceiling
    spastic = np.array([name in ("BIClong", "BRA") for name in names])
    for k, row in enumerate(ctrl):
        expected = np.full(len(names), 0.02)
        if k >= 15:
            expected[spastic] += reflex
        np.testing.assert_allclose(row, expected, atol=1e-12, err_msg=f"step {k}")


def test_reset_and_first_sample_fill_the_history(elbow: object) -> None:
    """Before D steps have passed the reflex sees the first sample (a person at rest before):
    a muscle already stretched at step 0 fires at once; reset starts over."""
    s = DriveSettings(length_threshold=1.0, length_gain=1.0, reflex_max=1.0, delay=0.1,
                      spastic_muscles=("BRA",))
    drive = NeuralDrive(elbow, s)
    data = fake_data(elbow)
    for name in drive.geometry.names:
        set_normalised(drive, data, name, 0.5, 0.0)
    set_normalised(drive, data, "BRA", 1.25, 0.0)
    bra = drive.geometry.names.index("BRA")
    drive.step(data)
    assert drive.reflex[bra] == pytest.approx(0.25)
    set_normalised(drive, data, "BRA", 0.5, 0.0)
    for _ in range(drive.delay_steps):
        drive.step(data)
        assert drive.reflex[bra] == pytest.approx(0.25)  # still the delayed first sample
    drive.step(data)
    assert drive.reflex[bra] == 0.0
    drive.reset()
    set_normalised(drive, data, "BRA", 1.5, 0.0)
    drive.step(data)
    assert drive.reflex[bra] == pytest.approx(0.5)


def test_ctrl_is_clipped_to_the_ctrlrange(elbow: object) -> None:
    """No tone and no reflex still writes the actuator's lower ctrl limit (0.001 in MyoSuite's
    models); an excitation above 1 is clipped to 1."""
    drive = NeuralDrive(elbow, DriveSettings(tone=0.0))
    data = fake_data(elbow)
    drive.step(data)
    np.testing.assert_allclose(data.ctrl, 0.001)
    loud = NeuralDrive(elbow, DriveSettings(tone=1.5))
    loud.step(data)
    np.testing.assert_allclose(data.ctrl, 1.0)


def test_fatigue_follows_its_equation_and_caps_the_excitation(elbow: object) -> None:
    """dF/dt = f u - r F by Euler at the model's step, the excitation capped at 1 - F."""
    f, r = 0.5, 0.1
    drive = NeuralDrive(elbow, DriveSettings(tone=0.9, fatigue_rate=f, recovery_rate=r))
    data = fake_data(elbow)
    dt = float(elbow.opt.timestep)  # type: ignore[attr-defined]
    fatigued = 0.0
    for _ in range(2000):
        drive.step(data)
        u = min(0.9, 1.0 - fatigued)
        assert data.ctrl[0] == pytest.approx(u, abs=1e-12)
        fatigued += dt * (f * u - r * fatigued)
    np.testing.assert_allclose(drive.fatigue, fatigued, rtol=1e-12)
    assert 1.0 - fatigued < 0.9  # fatigue has capped the tone


def test_voluntary_activation_helps_the_intended_movement(elbow: object) -> None:
    """Intending elbow flexion shortens the flexors: they are excited by g_vol times their
    intended shortening (moment arm x intent / L0), the lengthening triceps not at all."""
    import mujoco
    drive = NeuralDrive(elbow, DriveSettings(voluntary_gain=0.2))
    data = mujoco.MjData(elbow)
    data.qpos[:] = [0.0, 1.0]
    mujoco.mj_forward(elbow, data)
    drive.intent = np.array([0.0, 1.0])  # rad/s of elbow flexion
    drive.step(data)
    names = drive.geometry.names
    moment = np.zeros((elbow.nu, elbow.nv))  # type: ignore[attr-defined]
    mujoco.mju_sparse2dense(moment, data.actuator_moment, data.moment_rownnz,
                            data.moment_rowadr, data.moment_colind)
    shortening = -moment[drive.geometry.actuators, 1] * drive.geometry.scale
    expected = np.clip(0.2 * np.maximum(shortening, 0.0), 0.001, 1.0)
    np.testing.assert_allclose(drive.excitation, expected, rtol=1e-12)
    flexors = [names.index(n) for n in ("BIClong", "BICshort", "BRA")]
    triceps = [names.index(n) for n in ("TRIlong", "TRIlat", "TRImed")]
    assert np.all(drive.excitation[flexors] > 0.01)
    np.testing.assert_allclose(drive.excitation[triceps], 0.001)


def test_spastic_muscles_none_of_the_model_is_refused(elbow: object) -> None:
    with pytest.raises(ConfigError, match=r"person\.drive\.spastic_muscles"):
        NeuralDrive(elbow, DriveSettings(length_gain=1.0, reflex_max=1.0,
                                         spastic_muscles=("SOL", "GAS")))


def test_shipped_config_drives_nothing_and_a_grade_brings_its_preset(tmp_path: Path) -> None:
    shipped = drive_settings(load_config())
    assert not shipped.has_reflex and shipped.tone == 0.0 and shipped.delay == 0.1
    assert shipped.spastic_muscles == FLEXORS
    overlay = tmp_path / "mas2.yaml"
    overlay.write_text("plant_simulator:\n  ros__parameters:\n    person:\n      drive:\n"
                       "        mas_grade: '2'\n        reflex_delay: 0.05\n")
    graded = drive_settings(load_config(str(overlay)))
    preset = MAS_DRIVE_PRESETS["2"]
    assert (graded.length_gain, graded.velocity_gain, graded.length_threshold) == \
        (preset.length_gain, preset.velocity_gain, preset.length_threshold)
    assert graded.delay == 0.05  # the config's, not the preset's


def test_a_grade_and_custom_values_together_are_refused(tmp_path: Path) -> None:
    overlay = tmp_path / "both.yaml"
    overlay.write_text("plant_simulator:\n  ros__parameters:\n    person:\n      drive:\n"
                       "        mas_grade: '1'\n        length_gain: 0.5\n")
    with pytest.raises(ConfigError, match=r"person\.drive\.length_gain"):
        load_config(str(overlay))


def test_presets_grow_with_the_grade() -> None:
    """Gains, ceiling and tone rise and thresholds fall from grade to grade (Feng and Mak
    2002, Koo and Mak 2006); grade 0 has no reflex."""
    grades = ["1", "1+", "2", "3"]
    assert not MAS_DRIVE_PRESETS["0"].has_reflex
    for low, high in itertools.pairwise(grades):
        a, b = MAS_DRIVE_PRESETS[low], MAS_DRIVE_PRESETS[high]
        assert b.length_gain > a.length_gain and b.velocity_gain > a.velocity_gain
        assert b.reflex_max > a.reflex_max and b.tone > a.tone
        assert b.length_threshold < a.length_threshold
        assert b.velocity_threshold < a.velocity_threshold


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_the_strapped_plant_runs_the_configs_drive() -> None:
    """The strapped plant's default muscle drive is the config's (``drive_for``): none for the
    shipped keys (passive muscles, as before the drive existed), the neural drive of a MAS 3
    preset otherwise, which changes the trial (its tone pulls every muscle; the flexion
    movement shortens the spastic flexors), the same on a rerun (its delay lines are reset at
    every trial)."""
    from exo_ilc_ros.core.params.config import config_dir
    from exo_ilc_ros.core.person.experiment import StrappedExperiment

    short = {"trajectory.duration": 1.0, "musculoskeletal.settle_time": 0.0,
             "mass_uncertainty": 0.1}
    config = load_config(config_dir() / "myoelbow.yaml", overrides=short)
    shipped = StrappedExperiment(config)
    assert shipped.arm.drive is None
    u_ff = np.zeros_like(shipped.reference.position)
    passive = shipped.run_trial(u_ff, 1)
    spastic = StrappedExperiment(config.replace({"person.drive.mas_grade": "3"}))
    drive = spastic.arm.drive
    assert isinstance(drive, NeuralDrive)
    assert drive.delay_steps == 20  # 0.1 s at the strapped model's 5 ms
    first = spastic.run_trial(u_ff, 1)
    np.testing.assert_array_equal(spastic.run_trial(u_ff, 1).position, first.position)
    assert np.abs(first.position - passive.position).max() > 0.01
    assert np.all(drive.excitation >= MAS_DRIVE_PRESETS["3"].tone)


@pytest.mark.graph
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_the_graph_runs_a_spastic_person_as_simulate() -> None:
    """`exo-ilc run` with a MAS 2 person strapped in: plant_simulator builds the same neural
    drive from the config and resets it at every trial, so three 1 s trials through the real
    graph are the in-process trials (max |e| per trial and joint to 1e-9 rad)."""
    from exo_ilc_ros.core.params.config import config_dir
    from exo_ilc_ros.core.session.learning_session import run_trials
    from exo_ilc_ros.orchestration.graph import run_graph

    config = load_config(config_dir() / "myoelbow.yaml",
                         overrides={"trajectory.duration": 1.0, "max_trials": 3,
                                    "mass_uncertainty": 0.1,
                                    "musculoskeletal.settle_time": 0.2,
                                    "person.drive.mas_grade": "2"})
    local = run_trials(config)
    graph = run_graph(config, timeout=300.0)
    assert [s.trial for s in graph.summaries] == [1, 2, 3]
    np.testing.assert_allclose(graph.summary.max_abs_error, local.max_abs_errors,
                               rtol=0.0, atol=1e-9)
    passive = run_trials(config.replace({"person.drive.mas_grade": "custom"}))
    assert not np.allclose(passive.max_abs_errors, local.max_abs_errors)  # the drive acts
