"""Sessions that are interrupted resume exactly, and every session can be re-run exactly:
a learning virtual patient's state kept per profile version (re-run from a copy of the
profiles, from the session's bag, after a rollback; corrupt state refused), which unfinished
session a resume continues (two of one start: refused, naming both and how to resume each),
and `exo-ilc run --patient` killed mid-session then `--resume`d over real DDS ends with what an
uninterrupted session gives."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core import load_config
from exo_ilc_ros.core.config import scenario_path
from exo_ilc_ros.core.errors import ProfileError
from exo_ilc_ros.core.experiment import build_reference
from exo_ilc_ros.core.laws import FeedforwardUpdate
from exo_ilc_ros.core.patient import PatientLearning, PatientModel, true_error
from exo_ilc_ros.core.patient_states import PatientState, read_state
from exo_ilc_ros.core.profiles import ProfileBook
from exo_ilc_ros.core.therapy import ExerciseResult, prepare, run_exercise

ROOT = Path(__file__).resolve().parents[1]
SHORT_ROBUST = (ROOT / "config" / "robust.yaml").read_text() + \
    '"/**":\n  ros__parameters:\n    trajectory: {duration: 1.0}\n'
"""config/robust.yaml with trials of 1 s (101 samples)."""
LEARNING = load_config(ROOT / "config" / "robust.yaml", {"trajectory.duration": 1.0},
                       overlays=[scenario_path("learning")])
EXERCISE = "paper_quintic"


def _session(book: ProfileBook, trials: int = 3, new: bool = False) -> ExerciseResult:
    return run_exercise(prepare(LEARNING, book, "p1", EXERCISE, new), book, trials)


def _files(directory: Path) -> dict[str, str]:
    """sha256 of every file in ``directory`` (to show what was, or was not, rewritten)."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(directory.iterdir()) if p.is_file()}


def _replayed_state(start: PatientState, result: ExerciseResult) -> PatientState:
    """Oracle: the two-state model run by hand from ``start`` over the session's true errors."""
    model = PatientModel(result.config)
    learning = PatientLearning(model, start.fast.shape[0])
    learning.fast, learning.slow = start.fast.copy(), start.slow.copy()
    for record in result.result.records:
        learning.learn(record.trial, true_error(record))
    return PatientState(learning.fast, learning.slow)


def test_a_learning_patients_session_reruns_exactly(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Sessions 1-3 of a learning patient: each version keeps the state its session started
    from (written once) and ended with (the two-state model by hand over its true errors).
    Session 2 re-run from a copy of the profiles as they were before it, and replayed from its
    bag, is the same to the bit; a rollback to v1 starts the next session from v1's patient
    state; a corrupt state file is refused by name and kept."""
    book = ProfileBook(tmp_path / "a")
    first = _session(book, new=True)
    directory = book.directory("p1", EXERCISE)
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    config = tmp_path / "short.yaml"
    config.write_text(SHORT_ROBUST)
    common = ["simulate", "--config", str(config), "--scenario", "learning", "--patient", "p1",
              "--trials", "3", "--profiles", str(tmp_path / "a"), "--quiet"]
    assert main([*common, "--bag", str(tmp_path / "bags")]) == 0  # session 2, recorded
    (bag,) = (tmp_path / "bags").iterdir()
    kept = _files(directory)
    third = _session(book)
    assert third.version == 3
    after = _files(directory)
    assert {k: after[k] for k in kept if k.startswith("v0001") or k.startswith("v0002")} == \
        {k: v for k, v in kept.items() if k.startswith("v0001") or k.startswith("v0002")}

    index = book.require_index("p1", EXERCISE)
    samples = build_reference(LEARNING).samples
    starts = [read_state(directory, e["patient_start"]) for e in index["versions"]]
    ends = [read_state(directory, e["patient_state"]) for e in index["versions"]]
    assert starts[0].equals(PatientState.zeros(samples, 3))
    assert ends[0].equals(_replayed_state(starts[0], first))
    assert starts[1].equals(ends[0]) and starts[2].equals(ends[1])
    assert ends[2].equals(_replayed_state(starts[2], third))
    assert not ends[1].equals(ends[0]) and np.any(ends[1].slow != 0.0)
    assert not (directory / "virtual_patient.npz").exists()  # the latest only: not written

    # Re-run session 2 from the copy of the profiles made before it.
    rerun_book = ProfileBook(tmp_path / "b")
    rerun = _session(rerun_book)
    assert rerun.version == 2
    again = rerun_book.directory("p1", EXERCISE)
    for name in ("v0002.npz", "v0002.patient-start.npz", "v0002.patient.npz"):
        assert (again / name).read_bytes() == (directory / name).read_bytes(), name
    capsys.readouterr()
    # ... and from its bag: the config names profile.initial (v1) and patient.session 2.
    assert main(["simulate", "--replay", str(bag)]) == 0
    captured = capsys.readouterr()
    assert "3 trials compared, identical to the recording" in captured.out, captured

    # A rollback comes with the patient state its version ended with.
    assert main(["profiles", "--profiles", str(tmp_path / "a"), "rollback", "p1", EXERCISE,
                 "1"]) == 0
    fourth = _session(book, trials=1)
    assert fourth.version == 4 and fourth.started_from == 1
    entry = book.require_index("p1", EXERCISE)["versions"][3]
    assert read_state(directory, entry["patient_start"]).equals(ends[0])

    # A corrupt state file is refused by name, before anything runs, and kept.
    state_file = directory / "v0004.patient.npz"
    state_file.write_bytes(state_file.read_bytes()[:-3] + b"xyz")
    before = _files(directory)
    with pytest.raises(ProfileError, match=r"v0004\.patient\.npz: corrupt virtual patient"):
        _session(book)
    assert _files(directory) == before


def test_resume_says_which_unfinished_session(tmp_path: Path) -> None:
    """Two sessions begun from v1 at once and both left unfinished: a resume that does not
    say which is refused naming both; `begin` with the version continues exactly that one and
    lists the resume in its provenance; a complete version is never reopened."""
    config = load_config(ROOT / "config" / "robust.yaml", {"trajectory.duration": 1.0})
    book = ProfileBook(tmp_path)
    run_exercise(prepare(config, book, "p1", EXERCISE, True), book, 1)
    start = book.latest("p1", EXERCISE)
    reference = build_reference(config)
    a = book.begin("p1", EXERCISE, config, reference, start, "sa")
    b = book.begin("p1", EXERCISE, config, reference, start, "sb")
    a.save(1, FeedforwardUpdate(np.ones(reference.position.shape)), [0.0] * 3)
    with pytest.raises(ProfileError, match="versions v2, v3 are all unfinished sessions"):
        book.begin("p1", EXERCISE, config, reference, start, "s", reopen=True)
    resumed = book.begin("p1", EXERCISE, config, reference, start, "sc", reopen=b.version)
    assert resumed.version == 3 and resumed.created == b.created
    resumed.save(2, FeedforwardUpdate(np.zeros(reference.position.shape)), [0.0] * 3,
                 complete=True)
    entry = book.require_index("p1", EXERCISE)["versions"][2]
    assert entry["session"] == "sb" and [r["session"] for r in entry["resumed"]] == ["sc"]
    assert entry["resumed"][0]["after_trials"] == 0
    with pytest.raises(ProfileError, match="version 3 is complete"):
        book.begin("p1", EXERCISE, config, reference, start, "sd", reopen=3)
    with pytest.raises(ProfileError, match="began from v1 with config"):
        book.begin("p1", EXERCISE, config.replace({"control.kp": [1.0, 1.0, 1.0]}),
                   reference, start, "se", reopen=2)
