"""Therapy sessions: profiles per patient and exercise (start, kill, rollback, refusal of bad
input with nothing overwritten), metrics against hand-computed cases, and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core import ConfigError, Experiment, TrialRecord, load_config
from exo_ilc_ros.core.errors import ProfileError
from exo_ilc_ros.core.persistence.profiles import ProfileBook
from exo_ilc_ros.core.programs.metrics import (
    PassiveArm,
    TrialMetrics,
    gravity_compensation,
    required_torque,
    sparc,
    trial_metrics,
    velocity_slope,
)
from exo_ilc_ros.core.programs.therapy import prepare, run_exercise

ROOT = Path(__file__).resolve().parents[1]
ROBUST = load_config(ROOT / "config" / "robust.yaml", {"max_trials": 6})


def snapshot(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` and its bytes (to show nothing was overwritten)."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()}


def session(book: ProfileBook, patient: str = "p1", exercise: str = "paper_quintic",
            trials: int = 6, new: bool = False, config=ROBUST):  # type: ignore[no-untyped-def]
    return run_exercise(prepare(config, book, patient, exercise, new), book, trials)


def test_second_session_starts_from_the_profile(tmp_path: Path) -> None:
    """Session 2 runs trial 1 with the feed-forward session 1 learned last: its trial-1 max |e|
    equals session 1's trial 7 (what an uninterrupted run would do), far below trial 1's."""
    book = ProfileBook(tmp_path)
    first = session(book, new=True)
    assert first.version == 1 and first.started_from is None
    second = session(book)
    assert second.started_from == 1 and second.version == 2
    final = np.max(first.result.records[-1].max_abs_error)
    start = np.max(second.result.records[0].max_abs_error)
    assert start <= 1.5 * final
    assert np.max(first.result.records[0].max_abs_error) > 100 * start
    straight = Experiment(ROBUST).run_trial(first.result.final.feedforward, 7)  # type: ignore
    np.testing.assert_array_equal(second.result.records[0].position, straight.position)
    index = book.require_index("p1", "paper_quintic")
    assert index["current"] == 2 and index["versions"][1]["trials_total"] == 12
    assert index["versions"][1]["status"] == "complete"


def test_a_killed_session_keeps_every_trial_it_learned(tmp_path: Path) -> None:
    book = ProfileBook(tmp_path)
    prepared = prepare(ROBUST, book, "p1", "paper_quintic", new_patient=True)
    seen: list[TrialRecord] = []

    def kill_after_three(record: TrialRecord) -> None:
        seen.append(record)
        if record.trial == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_exercise(prepared, book, 6, on_trial=kill_after_three)
    profile = book.load("p1", "paper_quintic")
    assert profile.provenance["trials"] == 3 and profile.provenance["status"] == "in_progress"
    # What trial 4 would have used: the law's update from trial 3.
    from exo_ilc_ros.core.learning.factory import build_law

    law = build_law(prepared.config)
    np.testing.assert_array_equal(profile.feedforward, law.update(seen[2]).feedforward)
    again = session(book)
    assert again.started_from == 1


def test_unknown_patient_and_exercise_are_named(tmp_path: Path) -> None:
    book = ProfileBook(tmp_path)
    session(book, new=True)
    before = snapshot(tmp_path)
    with pytest.raises(ProfileError, match=r"unknown patient 'p2'.*known: p1"):
        prepare(ROBUST, book, "p2", "paper_quintic")
    with pytest.raises(ConfigError, match="unknown exercise 'juggling'"):
        prepare(ROBUST, book, "p1", "juggling")
    with pytest.raises(ProfileError, match="letters, digits"):
        prepare(ROBUST, book, "../etc", "paper_quintic", new_patient=True)
    with pytest.raises(ProfileError, match="already has profiles"):
        prepare(ROBUST, book, "p1", "paper_quintic", new_patient=True)
    assert snapshot(tmp_path) == before


def test_a_profile_of_another_model_or_reference_is_refused(tmp_path: Path) -> None:
    book = ProfileBook(tmp_path)
    session(book, new=True)
    before = snapshot(tmp_path)
    heavier = ROBUST.replace({"model.link_masses": [0.0, 1.6, 1.1]})
    with pytest.raises(ProfileError, match=r"another model: model\.link_masses \[0\.0, 1\.4"):
        prepare(heavier, book, "p1", "paper_quintic")
    longer = ROBUST.replace({"trajectory.duration": 6.0})
    with pytest.raises(ProfileError, match=r"another reference: 501 samples.*now 601"):
        prepare(longer, book, "p1", "paper_quintic")
    assert snapshot(tmp_path) == before
    # The plant (the patient's arm) may change between sessions: that is accepted.
    prepare(ROBUST.replace({"mass_uncertainty": 0.12}), book, "p1", "paper_quintic")


def test_corrupt_profile_files_are_refused_and_kept(tmp_path: Path) -> None:
    book = ProfileBook(tmp_path)
    session(book, new=True)
    data = tmp_path / "p1" / "paper_quintic" / "v0001.npz"
    blob = bytearray(data.read_bytes())
    blob[200] ^= 0xFF
    data.write_bytes(bytes(blob))
    before = snapshot(tmp_path)
    with pytest.raises(ProfileError, match=r"v0001\.npz: corrupt profile file"):
        prepare(ROBUST, book, "p1", "paper_quintic")
    assert main(["simulate", "--patient", "p1", "--profiles", str(tmp_path), "--trials", "2",
                 "--quiet"]) == 2
    assert snapshot(tmp_path) == before
    index = tmp_path / "p1" / "paper_quintic" / "index.json"
    index.write_text("{not json")
    before = snapshot(tmp_path)
    with pytest.raises(ProfileError, match=r"index\.json: corrupt profile index"):
        prepare(ROBUST, book, "p1", "paper_quintic")
    assert snapshot(tmp_path) == before


def test_rollback_and_the_profiles_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                           ) -> None:
    book = ProfileBook(tmp_path)
    session(book, new=True, trials=2)
    session(book, trials=2)
    root = ["profiles", "--profiles", str(tmp_path)]
    assert main([*root, "list"]) == 0
    assert "p1: paper_quintic" in capsys.readouterr().out
    assert main([*root, "show", "p1", "paper_quintic"]) == 0
    shown = capsys.readouterr().out
    assert " * v2" in shown and "   v1" in shown and "deg" in shown  # for a therapist: degrees
    assert main([*root, "rollback", "p1", "paper_quintic", "1"]) == 0
    assert book.latest("p1", "paper_quintic").version == 1  # type: ignore[union-attr]
    third = session(book, trials=1)
    assert third.started_from == 1 and third.version == 3  # nothing deleted, v3 appended
    out = tmp_path / "v1.json"
    assert main([*root, "export", "p1", "paper_quintic", str(out), "--version", "1"]) == 0
    exported = json.loads(out.read_text())
    np.testing.assert_array_equal(exported["feedforward"],
                                  book.load("p1", "paper_quintic", 1).feedforward)
    assert main([*root, "show", "p9", "paper_quintic"]) == 2
    assert "unknown patient 'p9'" in capsys.readouterr().err
    assert main([*root, "rollback", "p1", "paper_quintic", "7"]) == 2
    assert "no version 7" in capsys.readouterr().err


# --- metrics ------------------------------------------------------------------------------

def test_metrics_by_hand() -> None:
    """Effort a quarter of the required torque: the patient's share is 3/4 on every joint;
    RMS and peak error of a constant offset; the slope of 2 qdot + 1 is 2."""
    config = load_config()
    experiment = Experiment(config)
    ref = experiment.reference
    plant = experiment.plant
    q = ref.position - 0.01
    required = required_torque(plant, q, ref.velocity, ref.period)
    record = TrialRecord(1, ref, q, ref.velocity, np.ones_like(q), np.zeros_like(q),
                         0.25 * required)
    m = trial_metrics(record, experiment.nominal, plant)
    np.testing.assert_allclose(m.patient_share, 0.75, rtol=1e-12)
    assert m.patient_share_total == pytest.approx(0.75, rel=1e-12)
    np.testing.assert_allclose(m.rms_error, 0.01, rtol=1e-9)
    np.testing.assert_allclose(m.max_error, 0.01, rtol=1e-9)
    np.testing.assert_allclose(m.feedforward_rms, 1.0)
    # The passive arm's friction and stiffness are part of what the movement requires.
    passive = PassiveArm(np.full(3, 0.5), np.full(3, 0.2), 0.1, np.full(3, 2.0),
                         np.array([0.0, 0.0, 0.3]))
    torque = passive.torque(q, ref.velocity)
    np.testing.assert_allclose(torque[100], 0.5 * ref.velocity[100]
                               + 0.2 * np.tanh(ref.velocity[100] / 0.1)
                               + 2.0 * (q[100] - [0.0, 0.0, 0.3]))
    with_arm = required + torque
    record = TrialRecord(1, ref, q, ref.velocity, np.ones_like(q), np.zeros_like(q),
                         0.5 * with_arm)
    assert trial_metrics(record, experiment.nominal, plant, passive).patient_share_total == \
        pytest.approx(0.5, rel=1e-12)
    velocity = np.linspace(-1.0, 1.0, 11)[:, None] * [1.0, 3.0]
    np.testing.assert_allclose(velocity_slope(2.0 * velocity + 1.0, velocity), [2.0, 2.0])
    # At q = 0 the arm hangs straight down: no gravity torque.
    np.testing.assert_allclose(gravity_compensation(experiment.nominal, np.zeros((1, 3))), 0.0,
                               atol=1e-12)
    # Round trip through the trial summary (what a bag files).
    names = config["joint_names"]
    values = dict(m.summary_values(names))
    back = TrialMetrics.from_summary(1, values, names)
    assert back is not None and back.to_json() == m.to_json()


def test_sparc_prefers_smooth_movements() -> None:
    """One bell-shaped speed profile is smoother (SPARC nearer 0) than the same with a tremor;
    a minimum-jerk profile gives about -1.6 (Balasubramanian et al. 2015, Fig. 4)."""
    t = np.linspace(0.0, 1.0, 101)
    bell = 30 * t**2 * (1 - t) ** 2
    tremor = bell * (1.0 + 0.3 * np.sin(2 * np.pi * 8 * t))
    smooth = sparc(bell, 100.0)
    assert -1.7 < smooth < -1.4
    assert sparc(tremor, 100.0) < smooth - 0.5


# --- through the graph --------------------------------------------------------------------

@pytest.mark.graph
def test_graph_session_from_the_profile_equals_in_process(tmp_path: Path) -> None:
    """`exo-ilc run --patient` twice (the second from the profile the first wrote through the
    graph) gives the per-trial numbers and the profile of `exo-ilc simulate --patient` twice,
    to 1e-9; the metrics are in the JSON. A short exercise of the user's own file (1 s), a
    patient with sensor noise and start offsets: session 2 draws its own (patient.session 2)
    in the graph's plant as in-process."""
    import subprocess
    import sys

    exercises = tmp_path / "exercises.yaml"
    exercises.write_text("exercises:\n  lift:\n    points: [[0, 0, 0], [0.4, 0.2, 0.3], "
                         "[0.1, 0.1, 0.1]]\n    durations: [0.5, 0.5]\n")
    config = tmp_path / "therapy.yaml"
    config.write_text(f'"/**":\n  ros__parameters:\n    exercise:\n      file: "{exercises}"\n'
                      "plant_simulator:\n  ros__parameters:\n    patient:\n"
                      "      sensor: {position_noise: 2.0e-5}\n"
                      "      initial: {position_sd: 0.0005, velocity_sd: 0.003}\n")

    def exo_ilc(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", *args], text=True,
                              capture_output=True, timeout=240, stdin=subprocess.DEVNULL,
                              check=False, cwd=tmp_path)

    runs = {}
    for command, extra in (("simulate", []), ("run", ["--no-bag"])):
        profiles = tmp_path / f"profiles_{command}"
        common = [command, *extra, "--config", str(config), "--patient", "p1", "--exercise",
                  "lift", "--trials", "2", "--profiles", str(profiles), "--quiet"]
        out = tmp_path / f"{command}.json"
        if command == "simulate":  # in this process: two fewer interpreter start-ups
            assert main([*common, "--new-patient"]) == 0
            assert main([*common, "--json", str(out)]) == 0
        else:
            first = exo_ilc(*common, "--new-patient")
            assert first.returncode == 0, first.stderr[-3000:]
            second = exo_ilc(*common, "--json", str(out))
            assert second.returncode == 0, second.stderr[-3000:]
            assert "from profile v1" in second.stderr
        runs[command] = (json.loads(out.read_text()), ProfileBook(profiles).load("p1", "lift"))
    (graph, graph_profile), (local, local_profile) = runs["run"], runs["simulate"]
    (g,), (r,) = graph["runs"], local["runs"]
    for key in ("max_abs_error", "max_abs_feedforward", "max_abs_effort"):
        np.testing.assert_allclose([t[key] for t in g["trials"]], [t[key] for t in r["trials"]],
                                   rtol=0.0, atol=1e-9, err_msg=key)
    assert graph_profile.version == local_profile.version == 2
    assert graph_profile.provenance["started_from"] == 1
    assert graph_profile.provenance["patient_session"] == 2
    assert local_profile.provenance["patient_session"] == 2
    assert g["therapy"]["patient_session"] == r["therapy"]["patient_session"] == 2
    np.testing.assert_allclose(graph_profile.feedforward, local_profile.feedforward, atol=1e-9)
    assert [m["trial"] for m in g["therapy"]["metrics"]] == [1, 2]
    np.testing.assert_allclose(g["therapy"]["metrics"][-1]["max_error"],
                               r["therapy"]["metrics"][-1]["max_error"], atol=1e-9)


def test_session_plan_and_flag_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                      ) -> None:
    """--session runs the plan's exercises with their trials, each saved; therapy flags
    without --patient and contradictory flags are refused naming the flag."""
    exercises = tmp_path / "exercises.yaml"
    exercises.write_text(
        "exercises:\n  up: {points: [[0, 0, 0], [0.3, 0.2, 0.2]], durations: [0.5]}\n"
        "  down: {points: [[0.3, 0.2, 0.2], [0, 0, 0]], durations: [0.5]}\n"
        "sessions:\n  short: [{exercise: up, trials: 2}, {exercise: down, trials: 3}]\n")
    config = tmp_path / "c.yaml"
    config.write_text(f'"/**":\n  ros__parameters:\n    exercise:\n      file: "{exercises}"\n')
    base = ["simulate", "--config", str(config), "--profiles", str(tmp_path / "p"), "--quiet"]
    assert main([*base, "--patient", "p1", "--new-patient", "--session", "short"]) == 0
    book = ProfileBook(tmp_path / "p")
    assert book.exercises("p1") == ["down", "up"]
    assert book.load("p1", "up").provenance["trials"] == 2
    assert book.load("p1", "down").provenance["trials"] == 3
    capsys.readouterr()
    for args, message in (
            (["--exercise", "up"], "--exercise: needs --patient ID"),
            (["--new-patient"], ": needs --patient ID"),
            (["--patient", "p1", "--session", "short", "--exercise", "up"],
             "--session: cannot be combined with --exercise"),
            (["--patient", "p1", "--session", "long"], "unknown session 'long'"),
            (["--patient", "p1", "--exercise", "up", "up"], "names an exercise twice"),
            (["--patient", "p1", "--mass-uncertainty", "0.1", "0.2"], "one value with"),
    ):
        before = snapshot(tmp_path / "p")
        assert main([*base, *args]) == 2, args
        assert message in capsys.readouterr().err, args
        assert snapshot(tmp_path / "p") == before


def test_learning_patient_second_session_and_assist_as_needed(tmp_path: Path) -> None:
    """Under the learning patient with assist-as-needed (f 0.85): the learned feed-forward
    falls after its peak while the true error stays far inside the envelope, and a second
    session (robot profile and the virtual patient's memory) starts within 1.5x of the first
    session's final max |e| (bench/therapy_bench.py measures 100 trials)."""
    from exo_ilc_ros.core.params.config import scenario_path

    config = load_config(ROOT / "config" / "robust.yaml", {"assist_as_needed.enabled": True},
                         overlays=[scenario_path("learning")])
    book = ProfileBook(tmp_path)
    first = session(book, trials=30, new=True, config=config)
    uff = np.array([m.feedforward_rms.sum() for m in first.metrics])
    assert uff[-1] < 0.8 * uff.max()  # the robot hands over
    errors = np.array([m.max_error.max() for m in first.metrics])
    assert np.all(errors[5:] < 0.05)  # safety envelope 1 rad
    assert (tmp_path / "p1" / "paper_quintic" / "v0001.patient.npz").is_file()
    second = session(book, trials=2, config=config)
    final = np.max(first.result.records[-1].true_max_abs_error)
    start = np.max(second.result.records[0].true_max_abs_error)
    assert start <= 1.5 * final
