"""Patient populations, the certificate and the falsification (issue 33)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.analysis.certificate import read_rows, scenario_yaml, write_scenario
from exo_ilc_ros.analysis.falsification import ABORT_SCORE, Search, failure_score, falsify
from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core.loop.patient import MAS_PRESETS, patient_joint_indices, rest_positions
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.population.certificate import (
    PatientOutcome,
    certificate,
    longest_run,
    patient_cell,
    patient_config,
    patient_outcome,
)
from exo_ilc_ros.core.population.distributions import (
    COULOMB_MAX,
    ENCODER_RESOLUTION,
    MAS_ORDER,
    REST_BANDS,
    SOURCES,
    STIFFNESS_BANDS,
    VISCOUS_MAX,
    Patient,
    PopulationSpec,
    coordinate_family,
    draw_patient,
    draw_population,
    patient_from_unit,
    search_point,
)
from exo_ilc_ros.core.programs.study import CellResult, run_cell, true_max_abs_error
from exo_ilc_ros.core.session.learning_session import run_trials

ARMS = {"paper": None, "panda": config_dir() / "arms" / "panda.yaml",
        "ur5": config_dir() / "arms" / "ur5.yaml"}
PERSON = config_dir() / "person.yaml"


def _short(tmp_path: Path, duration: float = 1.0) -> Path:
    """An overlay that shortens the movement (a fast test)."""
    path = tmp_path / "short.yaml"
    path.write_text(f'"/**":\n  ros__parameters:\n    trajectory:\n      duration: {duration}\n')
    return path


def test_same_seed_same_patients_and_an_index_is_its_own() -> None:
    base = load_config()
    spec = PopulationSpec()
    a = draw_population(base, spec, 6, seed=3)
    b = draw_population(base, spec, 6, seed=3)
    assert [p.overrides for p in a] == [p.overrides for p in b]
    # patient 4 is the same whatever the population's size, and another seed is another one
    assert draw_patient(base, spec, 3, 4).overrides == a[4].overrides
    assert draw_patient(base, spec, 4, 4).overrides != a[4].overrides
    assert len({json.dumps(p.overrides, sort_keys=True) for p in a}) == 6


def test_sources_cover_every_drawn_quantity() -> None:
    spec = PopulationSpec(voluntary_share=0.5)
    for name, path in ARMS.items():
        overlays = [PERSON] if name == "panda" else []
        base = load_config(path, overlays=overlays)
        joints = schema.patient_joint_names(base.values)
        names = spec.coordinates(joints, bool(base["person.enabled"]))
        families = {coordinate_family(n) for n in names}
        assert families <= set(SOURCES), families - set(SOURCES)
        assert ("body" in families) == (name == "panda")
    for text in SOURCES.values():  # each names a publication (an author and a year) or the issue
        assert any(c.isdigit() for c in text)


@pytest.mark.parametrize("arm", list(ARMS))
def test_drawn_values_lie_in_the_published_ranges_on_any_arm(arm: str) -> None:
    overlays = [PERSON] if arm == "panda" else []
    base = load_config(ARMS[arm], overlays=overlays)
    spec = PopulationSpec()
    patients = draw_population(base, spec, 300, seed=0)
    start = np.asarray(base["trajectory.start"])
    grades = [p.mas_grade for p in patients]
    encoders = 0
    for i, p in enumerate(patients):
        o = p.overrides
        # valid through the schema (a URDF arm loads slowly: a dozen of them from the files)
        config = load_config(ARMS[arm], o, overlays=overlays) if i < 12 else base.replace(o)
        low, high = STIFFNESS_BANDS[p.mas_grade]
        k = np.asarray(o["patient.passive.stiffness"])
        assert np.all((k >= low) & (k <= high)) and np.all((k >= 0) & (k <= 4.0))
        assert np.all(np.asarray(o["patient.friction.viscous"]) <= VISCOUS_MAX)
        assert np.all(np.asarray(o["patient.friction.coulomb"]) <= COULOMB_MAX)
        assert 0.05 <= abs(o["mass_uncertainty"]) <= 0.15
        # the rest angle, in the arm's angles, is at most the grade's reach (<= 0.6) off the start
        rest = rest_positions(config)
        idx = patient_joint_indices(config)
        off = np.abs(rest[idx] - start[idx])
        assert np.all(off <= REST_BANDS[p.mas_grade] + 1e-12) and np.all(off <= 0.6 + 1e-12)
        assert o["patient.sensor.quantisation"] in (0.0, ENCODER_RESOLUTION)
        encoders += o["patient.sensor.quantisation"] > 0
        if arm == "panda":
            assert 1.5 <= o["person.height"] <= 1.88 and 50 <= o["person.body_mass"] <= 125
    # MAS prevalence: 27 % spastic (Watkins 2002), binomial 300 draws: within 4 sd
    spastic = sum(g != "0" for g in grades) / len(grades)
    assert abs(spastic - 0.27) < 4 * math.sqrt(0.27 * 0.73 / 300)
    assert set(grades) == {"0", "1", "1+", "2", "3"}
    assert abs(encoders / 300 - 0.5) < 4 * math.sqrt(0.25 / 300)
    assert pytest.approx(3.835e-4, rel=1e-3) == ENCODER_RESOLUTION


def _cell(index: int, worst: list[float], aborted: list[int] | None = None,
          failure: str | None = None) -> CellResult:
    e = np.array([[x, x / 2] for x in worst])
    ff = np.ones_like(e)
    return CellResult("L", f"patient {index}", 0.1, index, 0.005, 101, e, e, ff, ff,
                      np.zeros(len(worst), np.int64), aborted or [], failure)


def test_certificate_numbers_by_hand() -> None:
    trials = 25
    hi, lo = 0.02, 0.001
    results = [
        _cell(0, [hi] * 3 + [lo] * 22),  # settled at 4, first 4
        _cell(1, [hi] * 12 + [lo] * 13),  # settled at 13: within by 25, not by 10
        _cell(2, [hi] * 24 + [lo]),  # settled 25
        _cell(3, [hi] * 5 + [lo] * 20, aborted=[2, 3, 4]),  # 3 in a row
        _cell(4, [lo] * 5 + [hi] + [lo] * 19, aborted=[1, 6, 9]),  # 3 aborts, not in a row
        _cell(5, [hi] * 25),  # never within
        _cell(6, [lo] * 10 + [math.nan] * 15),  # not finite
        _cell(7, [lo] * 25),  # settled at 1
    ]
    outcomes = [patient_outcome(r.seed, r, trials) for r in results]
    assert [o.settled for o in outcomes] == [4, 13, 25, 6, 7, None, None, 1]
    assert [o.abort_run for o in outcomes] == [0, 0, 0, 3, 1, 0, 0, 0]
    cert = certificate("L", 8, trials, 0.005, outcomes)
    s = cert.summary()
    assert s["share_finite"] == 7 / 8 and s["share_bounded"] == 7 / 8
    assert s["share_within_by_10"] == 4 / 8  # 0, 3, 4, 7
    assert s["share_within_by_25"] == 6 / 8
    assert s["share_any_abort"] == 2 / 8 and s["share_abort_run_3"] == 1 / 8
    assert s["share_aborts_over_2"] == 2 / 8
    # settled: 1, 4, 6, 7, 13, 25, never, never -> median (the higher middle) 13; p95 never
    assert s["settled_median"] == 13 and s["settled_p95"] is None
    assert s["share_passes"] == 4 / 8  # 0, 1, 2 and 7
    assert not cert.passes and any("not finite" in r for r in cert.reasons())
    worst = cert.worst(3)
    assert worst[0].index == 6  # not finite first
    assert worst[1].index == 3  # then 3 aborts in a row
    assert longest_run([1, 2, 5, 6, 7, 9]) == 3 and longest_run([]) == 0
    good = certificate("L", 2, trials, 0.005, [outcomes[0], outcomes[7]])
    assert good.passes, good.reasons()
    assert PatientOutcome.from_json(outcomes[4].to_json()) == outcomes[4]


def test_falsification_score_orders_abort_and_nonfinite_above_any_error() -> None:
    r = [_cell(0, [0.3] * 5), _cell(1, [0.001] * 5, aborted=[2]), _cell(2, [math.nan] * 5)]
    scores = [failure_score(patient_outcome(c.seed, c, 5)) for c in r]
    assert scores[0] == pytest.approx(math.log10(0.3))
    assert scores[0] < ABORT_SCORE < scores[1] < scores[2]


def test_certify_command_small_population_json_rows_and_resume(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, png = tmp_path / "cert.json", tmp_path / "cert.png"
    args = ["certify", "--config", str(config_dir() / "robust.yaml"), "--scenario",
            str(_short(tmp_path)), "--population", "4", "--trials", "5", "--workers", "1",
            "--seed", "1", "--json", str(out), "--figure", str(png), "--worst", "2"]
    code = main(args)
    text = capsys.readouterr().out
    data = json.loads(out.read_text())
    assert code == (0 if data["summary"]["passes"] else 6)
    assert "Certificate of short: 4 patients x 5 trials" in text
    assert "the criteria need 25" in text and not data["summary"]["passes"]
    assert len(data["patients"]) == 4 and len(data["worst"]) == 2
    assert [p["index"] for p in data["patients"]] == [0, 1, 2, 3]
    # the JSON's numbers are the patients': recompute the shares from the per-patient entries
    finite = sum(p["finite"] for p in data["patients"]) / 4
    assert data["summary"]["share_finite"] == finite
    # each patient's overrides rerun in-process give its per-trial errors
    first = data["patients"][0]
    config = load_config(config_dir() / "robust.yaml", {**first["overrides"],
                         "max_trials": 5, "stop_when_settled": 0},
                         overlays=[_short(tmp_path)])
    worst = [float(np.max(true_max_abs_error(r))) for r in run_trials(config).records]
    assert np.allclose(worst, first["worst_error_per_trial"], rtol=1e-12)
    assert png.is_file() and png.stat().st_size > 10_000
    rows = tmp_path / "cert.rows.jsonl"
    assert len(rows.read_text().splitlines()) == 5  # the setup, then one line per patient
    # resume: a rows file with patient 3 cut off runs only patient 3 again
    lines = rows.read_text().splitlines()
    rows.write_text("\n".join(lines[:4]) + "\n" + lines[4][:30])
    assert main(args) == code
    again = json.loads(out.read_text())
    assert again["summary"] == data["summary"]
    assert len(read_rows(rows, again["setup"])) == 4


def test_falsification_finds_a_worse_patient_and_writes_it_loadable(tmp_path: Path) -> None:
    short = _short(tmp_path)
    law = str(config_dir() / "robust.yaml")
    base = load_config(law, overlays=[short])
    spec = PopulationSpec()
    names = spec.coordinates(schema.patient_joint_names(base.values), False)
    mild = {n: 0.0 for n in names}  # MAS 0, no stiffness, friction or encoder
    start = patient_from_unit(base, spec, mild, uniform_grades=True)
    start.overrides["patient.seed"] = 0
    start_run = patient_outcome(0, _run(law, [str(short)], start, 3), 3)
    found = falsify(base, spec, "robust", 3, Search(6, 0, mild))
    assert len(found) == 6 and found[0].score >= found[-1].score
    assert found[0].score > failure_score(start_run)
    # the worst found, written as a scenario, loads and reproduces its outcome
    path = write_scenario(tmp_path / "worst.yaml", found[0].patient, "found\nby a test")
    assert path.read_text().startswith("# found\n# by a test\n")
    config = load_config(law, {"max_trials": 3, "stop_when_settled": 0},
                         overlays=[short, path])
    worst = [float(np.max(true_max_abs_error(r))) for r in run_trials(config).records]
    assert np.allclose(worst, found[0].outcome.worst_error_per_trial, rtol=1e-12,
                       equal_nan=True)


def _run(law: str, overlays: list[str], patient: Patient, trials: int) -> CellResult:
    base = load_config(law, overlays=overlays)
    return run_cell(patient_cell("L", patient_config(base, patient, trials), patient))


def test_scenario_yaml_puts_each_key_in_its_section(tmp_path: Path) -> None:
    base = load_config(ARMS["panda"], overlays=[PERSON])
    patient = draw_patient(base, PopulationSpec(), 0, 0)
    text = scenario_yaml(patient.overrides, "x")
    path = tmp_path / "p.yaml"
    path.write_text(text)
    loaded = load_config(ARMS["panda"], overlays=[PERSON, path])
    for key, value in patient.overrides.items():
        assert loaded[key] == value, key


def test_the_search_reads_a_drawn_patient_as_the_same_patient() -> None:
    base = load_config()
    spec = PopulationSpec()
    for patient in draw_population(base, spec, 40, seed=5):
        again = patient_from_unit(base, spec, search_point(patient, spec), uniform_grades=True)
        assert {**again.overrides, "patient.seed": patient.overrides["patient.seed"]} == \
            patient.overrides


def test_voluntary_patients_and_every_grade_have_their_schema_keys() -> None:
    base = load_config()
    spec = PopulationSpec(voluntary_share=1.0)
    for patient in draw_population(base, spec, 5, seed=2):
        config = base.replace(patient.overrides)
        k = np.asarray(config["patient.voluntary.stiffness"])
        assert np.all((k >= 0) & (k <= 2.5)) and config["patient.voluntary.timing_sd"] <= 0.05
    assert set(MAS_ORDER) == set(MAS_PRESETS)
    with pytest.raises(ValueError, match="encoder_share"):
        PopulationSpec(encoder_share=1.5)


def test_a_rows_file_serves_any_population_size_and_loses_no_patient(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Patient i of a seed is the same whatever N: a run of 3 patients' rows gives the
    certificate of its first 2 without running any, and keeps the third; another seed's file
    is refused."""
    import exo_ilc_ros.analysis.certificate as certificate_module

    rows = tmp_path / "cert.rows.jsonl"
    args = ["certify", "--config", str(config_dir() / "robust.yaml"), "--scenario",
            str(_short(tmp_path)), "--trials", "3", "--workers", "1", "--rows", str(rows)]
    main([*args, "--population", "3", "--json", str(tmp_path / "three.json")])
    three = json.loads((tmp_path / "three.json").read_text())["patients"]

    def no_run(cells: list[object], *rest: object, **kw: object) -> list[object]:
        assert not cells, "a patient in the rows file was run again"
        return []
    monkeypatch.setattr(certificate_module, "run_cells", no_run)
    main([*args, "--population", "2", "--json", str(tmp_path / "two.json")])
    two = json.loads((tmp_path / "two.json").read_text())["patients"]
    assert two == three[:2]
    kept = [json.loads(x)["outcome"]["index"] for x in rows.read_text().splitlines()[1:]]
    assert sorted(kept) == [0, 1, 2]
    capsys.readouterr()
    assert main([*args, "--population", "2", "--seed", "4"]) == 2
    assert "another population or law" in capsys.readouterr().err
    # the same files after the law's values changed: refused, not resumed under another law
    (tmp_path / "short.yaml").write_text(
        '"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.1\n')
    assert main([*args, "--population", "2"]) == 2
    assert "another population or law" in capsys.readouterr().err
    assert sorted(json.loads(x)["outcome"]["index"]
                  for x in rows.read_text().splitlines()[1:]) == [0, 1, 2]


def test_pool_workers_run_one_blas_thread_and_give_the_same_bits(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The pool's workers start with one BLAS thread each unless the user set a count (then
    theirs), the parent's environment as it was after; patient_aware's identification (the
    BLAS-heavy part) gives the same bits in the workers as in this process."""
    import os

    from exo_ilc_ros.analysis import study
    from exo_ilc_ros.analysis.study import BLAS_THREADS, run_cells

    for name in BLAS_THREADS:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("MKL_NUM_THREADS", "3")
    with study._one_blas_thread():
        assert os.environ["OPENBLAS_NUM_THREADS"] == "1" == os.environ["OMP_NUM_THREADS"]
        assert os.environ["MKL_NUM_THREADS"] == "3"
    assert "OPENBLAS_NUM_THREADS" not in os.environ and os.environ["MKL_NUM_THREADS"] == "3"
    base = load_config(config_dir() / "patient_aware.yaml", overlays=[_short(tmp_path, 1.5)])
    spec = PopulationSpec()
    cells = [patient_cell("pa", patient_config(base, p, 4), p)
             for p in draw_population(base, spec, 2, seed=0)]
    serial = run_cells(cells, workers=1)
    pooled = run_cells(cells, workers=2)
    assert all(a.same_as(b) for a, b in zip(serial, pooled, strict=True))
