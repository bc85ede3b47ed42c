"""A patient's sessions one after another and at once: each session draws its own noise (the
virtual patient's ``patient.session`` is the profile version it writes) and a rerun of a
session reproduces it bit for bit; concurrent sessions of one patient and exercise each get
their own version under the profile's lock, none lost or overwritten (real processes)."""

from __future__ import annotations

import multiprocessing
import shutil
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core import load_config
from exo_ilc_ros.core.errors import ConfigError, ProfileError
from exo_ilc_ros.core.learning.laws import FeedforwardUpdate
from exo_ilc_ros.core.loop.patient import PatientModel
from exo_ilc_ros.core.params.config import scenario_path
from exo_ilc_ros.core.persistence.profiles import ProfileBook
from exo_ilc_ros.core.programs.therapy import ExerciseResult, prepare, run_exercise
from exo_ilc_ros.core.reference.build import build_reference
from exo_ilc_ros.core.session.learning_session import run_trials

ROOT = Path(__file__).resolve().parents[1]
SHORT = {"trajectory.duration": 1.0, "max_trials": 3}
REALISTIC = load_config(ROOT / "config" / "robust.yaml", SHORT,
                        overlays=[scenario_path("realistic")])
ROBUST = load_config(ROOT / "config" / "robust.yaml", SHORT)


def session(book: ProfileBook, new: bool = False, config=REALISTIC,  # type: ignore[no-untyped-def]
            trials: int = 3) -> ExerciseResult:
    return run_exercise(prepare(config, book, "p1", "paper_quintic", new), book, trials)


def records_equal(a: ExerciseResult, b: ExerciseResult) -> None:
    assert len(a.result.records) == len(b.result.records)
    for x, y in zip(a.result.records, b.result.records, strict=True):
        for name in ("position", "velocity", "effort", "feedforward", "true_position"):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name), err_msg=name)


def test_the_session_seeds_the_draws() -> None:
    """Session 1 (and a run outside any session) draws trial k from SeedSequence([seed, k]),
    the numbers of every run before sessions existed; session s >= 2 from [seed, s, k]."""
    samples = 11
    first = PatientModel(REALISTIC)
    third = PatientModel(REALISTIC.replace({"patient.session": 3}))
    for model, entropy in ((first, [0, 4]), (third, [0, 3, 4])):
        oracle = np.random.default_rng(np.random.SeedSequence(entropy)).standard_normal(
            (2, samples, 3))
        np.testing.assert_array_equal(model.draws(4, samples).noise[0], 2.0e-5 * oracle[0])
    assert not np.array_equal(third.draws(4, samples).initial, first.draws(4, samples).initial)
    with pytest.raises(ConfigError, match=r"patient\.session"):
        REALISTIC.replace({"patient.session": 0})


def test_sessions_differ_and_a_rerun_reproduces_one_exactly(tmp_path: Path) -> None:
    """Sessions 1 and 2 of one patient under the realistic patient: session 1 is the plain
    in-process run bit for bit; session 2 draws other noise, start offsets and jitters; run
    again from a copy of the profiles as they were before it, session 2 is the same to the bit
    (records, profile, provenance)."""
    book = ProfileBook(tmp_path / "a")
    first = session(book, new=True)
    plain = run_trials(REALISTIC, trials=3)
    for x, y in zip(first.result.records, plain.records, strict=True):
        np.testing.assert_array_equal(x.position, y.position)
        np.testing.assert_array_equal(x.true_position, y.true_position)
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    second = session(book)
    assert (first.config["patient.session"], second.config["patient.session"]) == (1, 2)
    one, two = (PatientModel(r.config).draws(1, 101) for r in (first, second))
    assert not np.array_equal(one.noise, two.noise)
    assert not np.array_equal(one.initial, two.initial)
    # Trial 1's start: x_d(0) plus the session's own offset.
    start = build_reference(REALISTIC).position[0]
    np.testing.assert_allclose(second.result.records[0].true_position[0], start + two.initial[0],
                               rtol=0.0, atol=1e-15)
    assert not np.allclose(second.result.records[0].true_position[0],
                           first.result.records[0].true_position[0], rtol=0.0, atol=1e-9)
    entry = book.load("p1", "paper_quintic", 2).provenance
    assert entry["patient_session"] == 2 and entry["patient_seed"] == 0
    assert second.to_json()["patient_session"] == 2

    rerun_book = ProfileBook(tmp_path / "b")
    rerun = session(rerun_book)
    assert rerun.config["patient.session"] == 2
    records_equal(rerun, second)
    np.testing.assert_array_equal(rerun_book.load("p1", "paper_quintic").feedforward,
                                  book.load("p1", "paper_quintic").feedforward)
    same = {"profile.initial": ""}  # the copy's path differs, its file does not
    assert rerun.config.replace(same).digest() == second.config.replace(same).digest()


def test_a_session_that_others_overtook_keeps_its_own_version(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two sessions both start from v1; the one that begins second writes v3, says it started
    from v1 without v2, and becomes current (the highest version); `profiles show` says so."""
    book = ProfileBook(tmp_path)
    session(book, new=True, config=ROBUST, trials=1)
    early, late = (prepare(ROBUST, book, "p1", "paper_quintic") for _ in range(2))
    assert early.start is not None and late.start is not None
    assert early.start.version == late.start.version == 1
    a = run_exercise(early, book, 1)
    b = run_exercise(late, book, 1)
    assert (a.version, b.version) == (2, 3) and a.started_from == b.started_from == 1
    index = book.require_index("p1", "paper_quintic")
    assert index["current"] == 3
    assert [v["not_included"] for v in index["versions"]] == [[], [], [2]]
    assert main(["profiles", "--profiles", str(tmp_path), "show", "p1", "paper_quintic"]) == 0
    shown = capsys.readouterr().out
    assert "from v1 (without v2: begun before it, not learned from)" in shown
    # A lower version saving later does not take `current` from a higher one.
    writer = book.begin("p1", "paper_quintic", ROBUST, build_reference(ROBUST), early.start)
    assert writer.version == 4 and book.require_index("p1", "paper_quintic")["current"] == 3
    shape = book.load("p1", "paper_quintic").feedforward.shape
    with pytest.raises(ProfileError, match="version 4 holds no trial yet"):
        book.load("p1", "paper_quintic", 4)
    writer.save(1, FeedforwardUpdate(np.zeros(shape)), [0.0, 0.0, 0.0])
    assert book.require_index("p1", "paper_quintic")["current"] == 4
    # A resumed run continues its unfinished version (the store is keyed by its session).
    again = book.begin("p1", "paper_quintic", ROBUST, build_reference(ROBUST), early.start,
                       reopen=True)
    assert again.version == 4 and again.config["patient.session"] == 4
    assert again.created == writer.created
    assert len(book.require_index("p1", "paper_quintic")["versions"]) == 4


WORKERS, SAVES = 4, 10


def _save_versions(root: str, worker: int, barrier: object) -> None:
    """One process of the concurrency test: SAVES sessions one after another, each begun from
    the latest profile and saved twice (in progress, complete), its feed-forward marked with
    (worker, session)."""
    book = ProfileBook(root)
    reference = build_reference(ROBUST)
    barrier.wait()  # type: ignore[attr-defined]
    for n in range(SAVES):
        start = book.latest("p1", "paper_quintic")
        writer = book.begin("p1", "paper_quintic", ROBUST, reference, start, f"w{worker}")
        marker = np.full(reference.position.shape, 100.0 * worker + n)
        writer.save(1, FeedforwardUpdate(marker), [0.0, 0.0, 0.0])
        writer.save(2, FeedforwardUpdate(marker), [0.0, 0.0, 0.0], complete=True)


def test_concurrent_sessions_get_distinct_versions_none_lost(tmp_path: Path) -> None:
    """4 processes x 10 sessions of one patient and exercise at once: 40 versions 1..40, each
    readable (sha256) with the feed-forward its own session saved, every (process, session)
    exactly once, all complete, the highest current."""
    context = multiprocessing.get_context("spawn")
    barrier = context.Barrier(WORKERS)
    processes = [context.Process(target=_save_versions, args=(str(tmp_path), w, barrier))
                 for w in range(WORKERS)]
    for process in processes:
        process.start()
    for process in processes:
        process.join(timeout=120)
    assert [p.exitcode for p in processes] == [0] * WORKERS
    book = ProfileBook(tmp_path)
    index = book.require_index("p1", "paper_quintic")
    versions = index["versions"]
    assert [v["version"] for v in versions] == list(range(1, WORKERS * SAVES + 1))
    assert index["current"] == WORKERS * SAVES
    markers = []
    for entry in versions:
        assert entry["status"] == "complete" and entry["patient_session"] == entry["version"]
        feedforward = book.load("p1", "paper_quintic", entry["version"]).feedforward
        assert np.all(feedforward == feedforward.flat[0])
        worker, n = divmod(int(feedforward.flat[0]), 100)
        assert entry["session"] == f"w{worker}"
        markers.append((worker, n))
        assert all((entry["started_from"] or 0) < v < entry["version"]
                   for v in entry["not_included"])
    assert sorted(markers) == [(w, n) for w in range(WORKERS) for n in range(SAVES)]
    # Each process's sessions in its own order.
    for w in range(WORKERS):
        mine = [n for worker, n in markers if worker == w]
        assert mine == sorted(mine)


def test_the_bag_of_a_later_session_replays_it_exactly(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    """The documented rerun: `exo-ilc simulate --replay BAG` of session 2's bag (its config
    holds patient.session 2 and the profile it started from) gives every trial again."""
    config = tmp_path / "c.yaml"
    config.write_text('"/**":\n  ros__parameters:\n    trajectory: {duration: 1.0}\n'
                      "plant_simulator:\n  ros__parameters:\n    patient:\n"
                      "      sensor: {position_noise: 2.0e-5}\n"
                      "      initial: {position_sd: 0.0005, velocity_sd: 0.003}\n")
    common = ["simulate", "--config", str(config), "--patient", "p1", "--trials", "2",
              "--profiles", str(tmp_path / "p"), "--quiet"]
    assert main([*common, "--new-patient"]) == 0
    assert main([*common, "--bag", str(tmp_path / "bags")]) == 0
    (bag,) = (tmp_path / "bags").iterdir()
    capsys.readouterr()
    assert main(["simulate", "--replay", str(bag)]) == 0
    assert "2 trials compared, identical to the recording" in capsys.readouterr().out
