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
from processes import sigkill_child

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core import load_config
from exo_ilc_ros.core.errors import ProfileError
from exo_ilc_ros.core.learning.laws import FeedforwardUpdate
from exo_ilc_ros.core.loop.patient import PatientLearning, PatientModel, true_error
from exo_ilc_ros.core.params.config import scenario_path
from exo_ilc_ros.core.persistence.patient_states import PatientState, read_state
from exo_ilc_ros.core.persistence.profiles import ProfileBook
from exo_ilc_ros.core.programs.therapy import ExerciseResult, prepare, run_exercise
from exo_ilc_ros.core.reference.build import build_reference

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

    # Through the graph a learning patient is refused before any node starts (its plant can
    # neither start from the stored state nor resume it).
    assert main(["run", "--no-bag", *common[1:], "--store", str(tmp_path / "s")]) == 2
    assert "patient.learning.gain: a learning virtual patient's therapy sessions run " \
        "in-process" in capsys.readouterr().err

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


def test_resume_says_which_unfinished_session(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
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
    capsys.readouterr()
    assert main(["profiles", "--profiles", str(tmp_path), "show", "p1", EXERCISE]) == 0
    shown = capsys.readouterr().out.splitlines()
    assert "in_progress" in shown[-3] and shown[-3].endswith("session sa"), shown
    assert shown[-2].endswith("session sb, resumed after 0 trials"), shown
    with pytest.raises(ProfileError, match="version 3 is complete"):
        book.begin("p1", EXERCISE, config, reference, start, "sd", reopen=3)
    with pytest.raises(ProfileError, match="began from v1 with config"):
        book.begin("p1", EXERCISE, config.replace({"control.kp": [1.0, 1.0, 1.0]}),
                   reference, start, "se", reopen=2)


# --- which session a resume continues (the CLI, before any node starts) ----------------------

def _unfinished_pair(tmp_path: Path) -> tuple[ProfileBook, Path, Path]:
    """v1 complete; v2 and v3 both begun from v1 (sessions s-a, s-b) and left unfinished, v2
    saving its trials in store A, v3 in store B."""
    config = load_config(ROOT / "config" / "robust.yaml", {"trajectory.duration": 1.0})
    book = ProfileBook(tmp_path / "profiles")
    run_exercise(prepare(config, book, "p1", EXERCISE, True), book, 1)
    start = book.latest("p1", EXERCISE)
    reference = build_reference(config)
    stores = tmp_path / "a", tmp_path / "b"
    for name, store in zip(("s-a", "s-b"), stores, strict=True):
        writer = book.begin("p1", EXERCISE, config, reference, start, name,
                            run_store=str(store))
        writer.save(1, FeedforwardUpdate(np.zeros(reference.position.shape)), [0.0] * 3)
    return book, *stores


def test_a_resume_that_could_continue_two_sessions_is_refused_naming_both(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two unfinished sessions of one start: `--resume` with the store of one continues that
    one; where both saved in the same store, or the store is neither's, it is refused (exit 2,
    nothing written) with both sessions listed and the exact command resuming each; a session
    id names one; an in-process session is not resumable through the graph."""
    import argparse

    from exo_ilc_ros.cli.therapy_resume import resumed_steps

    book, store_a, store_b = _unfinished_pair(tmp_path)
    config = load_config(ROOT / "config" / "robust.yaml", {"trajectory.duration": 1.0})
    plan: list[tuple[str, int | None]] = [(EXERCISE, 3)]

    def steps(resume: object, store: Path, argv: list[str] | None = None):  # type: ignore
        args = argparse.Namespace(patient="p1", resume=resume, argv=argv or ["run"])
        return resumed_steps(args, config, book, plan, store)

    for resume, store, version in ((True, store_a, 2), (True, store_b, 3), ("s-b", store_b, 3),
                                   ("v2", store_a, 2)):
        key, (step,) = steps(resume, store)
        assert step.reopen == version and key == f"s-{'ab'[version - 2]}"
        assert step.prepared is not None and step.prepared.start is not None
        assert step.prepared.start.version == 1
    with pytest.raises(ProfileError, match=r"saved its trials in .*/b, not .*/a"):
        steps("s-b", store_a)

    # The same store for both (their keys differ: the session number is in them).
    index_path = book.directory("p1", EXERCISE) / "index.json"
    index = json.loads(index_path.read_text())
    index["versions"][2]["run_store"] = str(store_a)
    index_path.write_text(json.dumps(index))
    profiles = str(tmp_path / "profiles")
    base = ["run", "--no-bag", "--patient", "p1", "--trials", "3", "--profiles", profiles,
            "--config", str(ROOT / "config" / "robust.yaml")]
    for store, says in ((store_a, f"2 unfinished sessions of patient 'p1' saved their trials "
                                  f"in {store_a}"),
                        (tmp_path / "c", f"no unfinished session of patient 'p1' saved its "
                                         f"trials in {tmp_path / 'c'}")):
        before = (tmp_path / "profiles").rglob("*")
        snapshot = {p: p.read_bytes() for p in before if p.is_file()}
        assert main([*base, "--store", str(store), "--resume"]) == 2
        err = capsys.readouterr().err
        assert says in err, err
        for key, version in (("s-a", 2), ("s-b", 3)):
            assert f"  session {key}: {EXERCISE} v{version} (in_progress, 1 trial, from v1" in err
            # after exo-ilc as typed here (issue 25: .venv/bin/exo-ilc where it is not on PATH)
            command = " " + " ".join([*base, "--store", str(store_a), "--resume", key])
            assert command in err, err
        assert {p: p.read_bytes() for p in (tmp_path / "profiles").rglob("*")
                if p.is_file()} == snapshot
    assert main([*base, "--store", str(store_a), "--resume", "s-x"]) == 2
    assert "no session s-x of patient 'p1'" in capsys.readouterr().err
    assert main(["run", "--no-bag", "--store", str(store_a), "--resume", "s-a"]) == 2
    assert "takes a session ('s-a') only with --patient" in capsys.readouterr().err

    # A session begun in-process keeps no run store: named, not resumed.
    config_short = load_config(ROOT / "config" / "robust.yaml", {"trajectory.duration": 1.0})
    start = book.load("p1", EXERCISE, 1)
    book.begin("p1", EXERCISE, config_short, build_reference(config_short), start, "s-c")
    with pytest.raises(ProfileError, match="began in-process"):
        steps("s-c", store_a)


def test_a_resumed_plan_skips_what_its_session_completed(tmp_path: Path) -> None:
    """Session s1 of a plan of three exercises stopped in the second: its resume does not run
    the first again (complete in s1; reported from its run store), continues the second's
    unfinished version from the version it began from, and begins the third (not begun in
    s1) from its latest profile."""
    import argparse

    from exo_ilc_ros.cli.therapy_resume import resumed_steps, stored_summary
    from exo_ilc_ros.core.session.learning_session import run_trials
    from exo_ilc_ros.core.session.summary import RunSummary

    exercises = tmp_path / "exercises.yaml"
    exercises.write_text(
        "exercises:\n  up: {points: [[0, 0, 0], [0.3, 0.2, 0.2]], durations: [0.5]}\n"
        "  down: {points: [[0.3, 0.2, 0.2], [0, 0, 0]], durations: [0.5]}\n"
        "  left: {points: [[0, 0, 0], [0.1, 0.3, 0.0]], durations: [0.5]}\n")
    config = load_config(ROOT / "config" / "robust.yaml", {"exercise.file": str(exercises)})
    book = ProfileBook(tmp_path / "p")
    store = tmp_path / "s"

    def version(name: str, session: str, complete: bool) -> int:
        start = book.latest("p1", name) if book.index("p1", name) else None
        cfg = config.replace({"exercise.name": name, "profile.initial":
                              "" if start is None else str(start.path.resolve())})
        shape = build_reference(cfg).position.shape
        writer = book.begin("p1", name, cfg, build_reference(cfg), start, session,
                            run_store=str(store))
        writer.save(1, FeedforwardUpdate(np.full(shape, 1.0)), [0.0] * 3, complete=complete)
        return writer.version

    for name in ("up", "down", "left"):
        version(name, "s0", True)  # an earlier session, complete
    assert version("up", "s1", True) == 2
    # Its trials in the run store, as the graph (or simulate --store: the same key) left them.
    v1 = book.load("p1", "up", 1)
    ran = run_trials(config.replace({"exercise.name": "up", "max_trials": 2,
                                     "profile.initial": str(v1.path.resolve()),
                                     "patient.session": 2}), store=store)
    assert version("down", "s1", False) == 2
    args = argparse.Namespace(patient="p1", resume=True, argv=["run"])
    key, (up, down, left) = resumed_steps(args, config, book, [("up", 2), ("down", 2),
                                                                ("left", 2)], store)
    assert key == "s1"
    assert up.done is not None and up.done["version"] == 2
    summary = stored_summary(up, store)  # the report includes it, as the first run gave it
    assert summary is not None
    assert summary.to_json()["trials"] == RunSummary.from_result(ran).to_json()["trials"]
    assert summary.extra["therapy"]["profile_version"] == 2
    assert len(summary.extra["therapy"]["metrics"]) == 2
    assert down.reopen == 2 and down.prepared is not None
    assert down.prepared.start is not None and down.prepared.start.version == 1
    assert left.reopen is None and left.prepared is not None
    assert left.prepared.start is not None and left.prepared.start.version == 1


# --- through the graph: killed mid-session, resumed -----------------------------------------

@pytest.mark.graph
def test_a_graph_session_killed_mid_session_resumes_exactly(tmp_path: Path) -> None:
    """`exo-ilc run --patient` (session 2 of a patient with sensor noise and start offsets,
    4 trials of 1 s) killed with kill -9 of ilc_supervisor after 2 trials: exit 3, the profile
    holds v2 in progress, and the command printed resumes exactly this session, even with
    another unfinished session begun from v1 meanwhile (v3, which the resume must not take).
    The resumed run ends with the table, the v2 file's bytes and the provenance of the same
    session run uninterrupted (in-process, from a copy of the profiles), but for the times,
    the session id and the record of the resume."""
    import subprocess
    import sys
    import time

    config_file = tmp_path / "c.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory: {duration: 1.0}\n'
                           "plant_simulator:\n  ros__parameters:\n    patient:\n"
                           "      sensor: {position_noise: 2.0e-5}\n"
                           "      initial: {position_sd: 0.0005, velocity_sd: 0.003}\n")
    profiles, reference_profiles = tmp_path / "p", tmp_path / "p_ref"
    store = tmp_path / "store"

    def common(root: Path) -> list[str]:
        return ["--config", str(config_file), "--patient", "p1", "--trials", "4",
                "--profiles", str(root), "--quiet"]

    assert main(["simulate", *common(profiles)[:-1], "--trials", "2", "--new-patient",
                 "--quiet"]) == 0
    shutil.copytree(profiles, reference_profiles)
    exo_ilc = [sys.executable, "-m", "exo_ilc_ros.cli.main"]
    process = subprocess.Popen([*exo_ilc, "run", "--no-bag", *common(profiles), "--store",
                                str(store)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               stdin=subprocess.DEVNULL, text=True)
    try:
        deadline = time.monotonic() + 180.0
        stored = 0
        while time.monotonic() < deadline and process.poll() is None and stored < 2:
            found = list(store.glob("*/index.json"))
            stored = len(json.loads(found[0].read_text())["trials"]) if found else 0
            time.sleep(0.01)
        assert stored >= 2, "two trials stored"
        err = sigkill_child(process, "ilc_supervisor")
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 3, err[-3000:]
    assert "node ilc_supervisor exited with code -9" in err
    assert f"to continue this session exactly (v2 of {EXERCISE})" in err
    book = ProfileBook(profiles)
    killed = book.require_index("p1", EXERCISE)["versions"][1]
    assert killed["status"] == "in_progress" and killed["trials"] in (2, 3), killed
    assert killed["run_store"] == str(store.resolve())
    session = killed["session"]
    # The command as typed here (issue 25): exo-ilc, .venv/bin/exo-ilc or python -m ...
    line = next(x for x in err.splitlines() if x.startswith("  ") and " run " in x and
                "--resume" in x)
    assert line.split()[-2:] == ["--resume", session] and "--store" in line, line
    words = line.split()

    # Another session begun from v1 and left unfinished, in a store of its own.
    config = load_config(config_file)
    start = book.load("p1", EXERCISE, 1)
    book.begin("p1", EXERCISE, config.replace({"profile.initial": str(start.path.resolve())}),
               build_reference(config), start, "other", run_store=str(tmp_path / "other"))

    out = tmp_path / "resumed.json"
    command = [*exo_ilc, *words[words.index("run"):], "--json", str(out)]
    resumed = subprocess.run(command, capture_output=True, text=True, timeout=240,
                             stdin=subprocess.DEVNULL, check=False)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert "(resuming v2)" in resumed.stderr, resumed.stderr[-3000:]

    local = tmp_path / "local.json"
    assert main(["simulate", *common(reference_profiles), "--json", str(local)]) == 0
    (graph,), (uninterrupted,) = (json.loads(p.read_text())["runs"] for p in (out, local))
    assert graph["trials"] == uninterrupted["trials"]  # exactly: floats through JSON
    assert graph["therapy"]["metrics"] == uninterrupted["therapy"]["metrics"]
    assert graph["therapy"]["profile_version"] == 2

    index = book.require_index("p1", EXERCISE)
    mine, theirs = index["versions"][1], index["versions"][2]
    assert theirs["status"] == "started" and theirs["session"] == "other"  # untouched
    assert index["current"] == 2
    directory, reference_directory = (ProfileBook(r).directory("p1", EXERCISE)
                                      for r in (profiles, reference_profiles))
    assert (directory / "v0002.npz").read_bytes() == \
        (reference_directory / "v0002.npz").read_bytes()
    expected = ProfileBook(reference_profiles).require_index("p1", EXERCISE)["versions"][1]
    differ = {"created", "updated", "session", "config_digest", "run_store", "resumed"}
    assert {k: v for k, v in mine.items() if k not in differ} == \
        {k: v for k, v in expected.items() if k not in differ}
    assert mine["status"] == "complete" and mine["trials"] == 4
    assert (mine["session"], mine["created"]) == (session, killed["created"])
    assert mine["config_digest"] == killed["config_digest"]  # the run it continues
    assert [r["after_trials"] for r in mine["resumed"]] == [killed["trials"]]


def test_a_save_interrupted_before_its_index_loses_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C (or kill -9) after a save replaced the version and patient state files but
    before it wrote the index: the index's sha256 no longer matches the files, which used to
    make the version refused as corrupt (every trial of the session lost). Now the listed files
    were kept as `.previous`: the version loads as the last completed save (trial 2 of 3, the
    same arrays as a 2-trial session), with its patient state, and the next session starts."""
    from exo_ilc_ros.core.persistence import profile_writer, profiles

    book = ProfileBook(tmp_path / "a")
    calls = {"index": 0}
    write = profiles.write_json_atomic

    def interrupted(path: Path, document: object) -> None:
        calls["index"] += 1
        if calls["index"] == 4:  # begin, trial 1, trial 2, then trial 3's save
            raise KeyboardInterrupt
        write(path, document)

    for module in (profiles, profile_writer):  # the book begins a version, its writer saves
        monkeypatch.setattr(module, "write_json_atomic", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _session(book, trials=3, new=True)
    for module in (profiles, profile_writer):
        monkeypatch.setattr(module, "write_json_atomic", write)
    directory = book.directory("p1", EXERCISE)
    assert (directory / "v0001.npz.previous").is_file()
    profile = book.load("p1", EXERCISE)
    assert profile.provenance["trials"] == 2
    two = _session(ProfileBook(tmp_path / "b"), trials=2, new=True)
    reference = ProfileBook(tmp_path / "b").load("p1", EXERCISE)
    np.testing.assert_array_equal(profile.feedforward, reference.feedforward)
    assert profile.patient_state is not None and reference.patient_state is not None
    assert profile.patient_state.equals(reference.patient_state)
    assert two.version == 1
    after = _session(book, trials=1)
    assert after.version == 2 and after.started_from == 1
