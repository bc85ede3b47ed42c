"""Populations of persons with muscles (issue 34 on issue 33's certificate): a patient drawn as
the strapped person's parameters (MAS grade -> the neural drive's preset, misalignment, strap
stiffness, mass error), each from its source, through the schema; the cuffs' peak forces per
patient in the rows and the JSON, the population's max and p95 in the certificate."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.analysis.certificate import format_certificate, read_rows, run_population
from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.person.cuffs import cuff_metrics
from exo_ilc_ros.core.person.neural_drive import MAS_DRIVE_PRESETS, drive_settings
from exo_ilc_ros.core.population.certificate import (
    PatientOutcome,
    certificate,
    patient_cell,
    patient_config,
    patient_outcome,
)
from exo_ilc_ros.core.population.distributions import (
    MAS_ORDER,
    MISALIGNMENT_OFFSET,
    MISALIGNMENT_ROTATION,
    SOURCES,
    STRAP_STIFFNESS_RANGE,
    PopulationSpec,
    coordinate_family,
    cube_coordinates,
    draw_patient,
    draw_population,
    patient_from_unit,
    search_point,
)
from exo_ilc_ros.core.programs.study import CellResult
from exo_ilc_ros.core.session.learning_session import run_trials

MYOELBOW = config_dir() / "myoelbow.yaml"
MYOARM = config_dir() / "myoarm.yaml"


def _short(tmp_path: Path) -> Path:
    """A 1 s movement and a 0.2 s settling (a fast test)."""
    path = tmp_path / "short.yaml"
    path.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'
                    'plant_simulator:\n  ros__parameters:\n    musculoskeletal:\n'
                    '      settle_time: 0.2\n')
    return path


@pytest.mark.parametrize("path", [MYOELBOW, MYOARM])
def test_a_person_is_drawn_as_its_parameters_each_from_a_source(path: Path) -> None:
    base = load_config(path)
    spec = PopulationSpec(encoder_share=0.0)
    names = cube_coordinates(base, spec)
    families = {coordinate_family(n) for n in names}
    assert families <= set(SOURCES), families - set(SOURCES)
    # the person's parameters, not torques on the exoskeleton's joints, sensors or a body
    assert families == {"mas", "mass", "misalignment", "strap"}
    patient = draw_patient(base, spec, 0, 0)
    assert not any(k.startswith("patient.") and k != "patient.seed" for k in patient.overrides)
    assert "MAS" in patient.describe() and "misaligned" in patient.describe()


def test_drawn_persons_lie_in_their_ranges_and_pass_the_schema() -> None:
    base = load_config(MYOELBOW)
    spec = PopulationSpec(encoder_share=0.0)
    patients = draw_population(base, spec, 300, seed=0)
    grades = []
    for i, p in enumerate(patients):
        o = p.overrides
        # through the schema: from the files for a few, the base's replace for the rest
        config = load_config(MYOELBOW, o) if i < 5 else base.replace(o)
        grades.append(str(config["person.drive.mas_grade"]))
        # the grade's preset is the drive's (tone and reflex as the preset says)
        settings = drive_settings(config)
        preset = MAS_DRIVE_PRESETS[p.mas_grade]
        assert (settings.tone, settings.velocity_gain, settings.reflex_max) == \
            (preset.tone, preset.velocity_gain, preset.reflex_max)
        offset = np.asarray(o["strapping.misalignment.offset"])
        assert np.linalg.norm(offset) <= MISALIGNMENT_OFFSET + 1e-9
        assert np.all(np.abs(o["strapping.misalignment.rotation"]) <= MISALIGNMENT_ROTATION)
        for key, (soft, stiff) in STRAP_STIFFNESS_RANGE.items():
            k = np.asarray(o[f"strapping.{key}"])
            assert np.all(k >= np.asarray(soft) - 1e-9) and np.all(k <= np.asarray(stiff) + 1e-9)
        assert 0.05 <= abs(o["mass_uncertainty"]) <= 0.15
    # the offset fills the 10 mm ball uniformly: P(|offset| < 5 mm) = 1/8 (4 sd of 300 draws)
    inner = np.mean([np.linalg.norm(p.overrides["strapping.misalignment.offset"]) < 5.0
                     for p in patients])
    assert abs(inner - 0.125) < 4 * math.sqrt(0.125 * 0.875 / 300)
    spastic = sum(g != "0" for g in grades) / len(grades)
    assert abs(spastic - 0.27) < 4 * math.sqrt(0.27 * 0.73 / 300)
    assert set(grades) == set(MAS_ORDER)
    # the schema refuses a person drawn outside its rules, naming the key
    bad = {**patients[0].overrides, "strapping.stiffness": [-1.0, 3700.0, 2250.0]}
    with pytest.raises(ConfigError, match=r"strapping\.stiffness"):
        base.replace(bad)
    with pytest.raises(ConfigError, match="mas_grade"):
        base.replace({**patients[0].overrides, "person.drive.mas_grade": "4"})


def test_a_drawn_person_is_the_same_whatever_n_and_the_search_reads_it_back() -> None:
    base = load_config(MYOELBOW)
    spec = PopulationSpec(encoder_share=0.0)
    five = draw_population(base, spec, 5, seed=7)
    assert draw_patient(base, spec, 7, 3).overrides == five[3].overrides
    assert draw_patient(base, spec, 8, 3).overrides != five[3].overrides
    for p in five:
        again = patient_from_unit(base, spec, search_point(p, spec), uniform_grades=True)
        assert {**again.overrides, "patient.seed": p.overrides["patient.seed"]} == p.overrides


def test_a_small_population_runs_with_its_cuff_forces_reproducibly(tmp_path: Path) -> None:
    """Two myoelbow patients, two trials, through the certificate's core (the rows file, a
    pool of one worker): each patient's peak cuff forces are the maximum over its trials of
    :func:`cuff_metrics` of its records run again in this process; patient 1 of a population
    of 2 is patient 1 of a population of 3; the rows file reads back to the same outcomes."""
    short = _short(tmp_path)
    base = load_config(MYOELBOW, overlays=[short])
    spec = PopulationSpec(encoder_share=0.0)
    trials = 2

    def cells(n: int) -> list:
        return [patient_cell("myoelbow", patient_config(base, p, trials), p)
                for p in draw_population(base, spec, n, seed=0)]
    rows = tmp_path / "rows.jsonl"
    setup = {"label": "myoelbow", "seed": 0, "trials": trials, "population": 2}
    outcomes = run_population(cells(2), trials, 1, None, rows, setup)
    assert [o.index for o in outcomes] == [0, 1]
    for o, patient in zip(outcomes, draw_population(base, spec, 2, seed=0), strict=True):
        assert o.peak_cuff_force is not None and o.peak_cuff_torque is not None
        records = run_trials(patient_config(base, patient, trials)).records
        peaks = np.max([cuff_metrics(np.asarray(r.cuff_wrench)) for r in records], axis=0)
        assert np.allclose(o.peak_cuff_force, peaks[:, 0], rtol=1e-12)
        assert np.allclose(o.peak_cuff_torque, peaks[:, 2], rtol=1e-12)
        assert all(f > 0.5 for f in o.peak_cuff_force)  # the person hangs in the cuffs
    # the rows file holds the cuff forces and reads back to the same outcomes
    lines = [json.loads(x) for x in rows.read_text().splitlines()]
    assert all("peak_cuff_force_N" in x["outcome"] for x in lines[1:])
    assert read_rows(rows, setup) == {o.index: o for o in outcomes}
    # patient 1 of 3 (another file, run afresh) is patient 1 of 2
    three = run_population(cells(3), trials, 1, None, None, setup)
    assert three[1] == outcomes[1]
    cert = certificate("myoelbow", 2, trials, 0.005, outcomes)
    summary = cert.summary()
    worst = [max(o.peak_cuff_force) for o in outcomes]
    assert summary["cuff_force_max_N"] == max(worst)
    assert summary["cuff_peaks_per_cuff"]["force_N"] == \
        [max(o.peak_cuff_force[c] for o in outcomes) for c in range(2)]
    assert "peak cuff force" in format_certificate(cert, {}, 2)


def _cell(index: int, forces: list[list[float]] | None) -> CellResult:
    e = np.full((len(forces or [[0]]), 3), 0.001)
    f = None if forces is None else np.asarray(forces, dtype=float)
    return CellResult("L", f"patient {index}", 0.1, index, 0.005, 101, e, e, e, e,
                      np.zeros(e.shape[0], np.int64), [], peak_cuff_force=f,
                      peak_cuff_torque=None if f is None else f / 100)


def test_cuff_force_numbers_by_hand() -> None:
    # 20 patients: worst cuff 10, 20, ..., 200 N (the forearm in odd patients)
    outcomes = []
    for i in range(20):
        worst = 10.0 * (i + 1)
        pair = [worst, worst / 2] if i % 2 == 0 else [worst / 2, worst]
        outcomes.append(patient_outcome(i, _cell(i, [[1.0, 1.0], pair]), 2))
    cert = certificate("L", 20, 2, 0.005, outcomes)
    s = cert.summary()
    assert s["cuff_force_max_N"] == 200.0
    # p95 of 10..200 N, linear between the 19th (190) and 20th (200) of 20: 190 + 0.05 * 10
    assert s["cuff_force_p95_N"] == pytest.approx(190.5)
    assert s["cuff_peaks_per_cuff"]["force_N"] == [190.0, 200.0]
    assert s["cuff_peaks_per_cuff"]["torque_Nm"] == pytest.approx([1.9, 2.0])
    assert outcomes[3].peak_cuff_force == (20.0, 40.0)
    assert PatientOutcome.from_json(outcomes[3].to_json()) == outcomes[3]
    # no person: no cuff numbers, and an older row without them reads back as none
    plain = patient_outcome(0, _cell(0, None), 1)
    assert plain.peak_cuff_force is None and "peak_cuff_force_N" not in plain.to_json()
    assert "cuff_force_max_N" not in certificate("L", 1, 1, 0.005, [plain]).summary()


def test_certify_refuses_sensors_or_voluntary_effort_for_a_person(
        capsys: pytest.CaptureFixture[str]) -> None:
    for flag in ("--encoder-share", "--voluntary-share"):
        code = main(["certify", "--config", str(MYOELBOW), "--population", "1", "--trials",
                     "1", "--workers", "1", flag, "0.5"])
        assert code == 2
        assert f"{flag}: is not drawn for a person with muscles" in capsys.readouterr().err


def test_the_study_json_carries_a_persons_cuff_forces_per_trial() -> None:
    from exo_ilc_ros.analysis.study import study_json

    with_person = _cell(0, [[10.0, 20.0], [30.0, math.nan]])
    cells = study_json({}, [], [with_person, _cell(1, None)])["cells"]
    assert cells[0]["peak_cuff_force_N"] == [[10.0, 20.0], [30.0, None]]
    assert cells[0]["peak_cuff_torque_Nm"] == [[0.1, 0.2], [0.3, None]]
    assert "peak_cuff_force_N" not in cells[1]
