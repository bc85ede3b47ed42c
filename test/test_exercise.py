"""Exercises (core/reference/exercise.py): piecewise quintics through rest points, the default
exercise is the paper's quintic bit for bit, the shipped file loads, bad files are refused naming
the key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core import ConfigError, QuinticTrajectory, SampledReference, load_config
from exo_ilc_ros.core.reference.build import build_reference
from exo_ilc_ros.core.reference.exercise import (
    PAPER_EXERCISE,
    Exercise,
    exercise_reference,
    exercises_path,
    load_book,
)


def test_default_exercise_is_the_papers_quintic_bit_for_bit() -> None:
    config = load_config()
    assert config["exercise.name"] == PAPER_EXERCISE and exercise_reference(config) is None
    expected = SampledReference.from_trajectory(QuinticTrajectory.rest_to_rest(
        config["trajectory.start"], config["trajectory.goal"], 5.0), 0.01)
    got = build_reference(config)
    for a, b in ((got.position, expected.position), (got.velocity, expected.velocity),
                 (got.acceleration, expected.acceleration)):
        np.testing.assert_array_equal(a, b)


def test_piecewise_quintic_rests_at_every_point() -> None:
    """Two segments of 1 s at 0.1 s: 21 samples; at t = 0, 1, 2 s the positions are the points,
    velocity and acceleration zero; the first half is eq (14) itself; the midpoint of a segment
    is the mean of its ends (the quintic is point-symmetric about it)."""
    points = np.array([[0.0, 1.0], [0.6, -1.0], [0.2, 1.0]])
    exercise = Exercise("test", points, np.array([1.0, 1.0]))
    ref = exercise.sample(0.1)
    assert ref.samples == 21
    for index, point in zip((0, 10, 20), points, strict=True):
        np.testing.assert_allclose(ref.position[index], point, atol=1e-12)
        np.testing.assert_allclose(ref.velocity[index], 0.0, atol=1e-12)
        np.testing.assert_allclose(ref.acceleration[index], 0.0, atol=1e-12)
    np.testing.assert_allclose(ref.position[5], [0.3, 0.0], atol=1e-12)
    np.testing.assert_allclose(ref.position[15], [0.4, 0.0], atol=1e-12)
    first = SampledReference.from_trajectory(QuinticTrajectory.rest_to_rest(
        points[0], points[1], 1.0), 0.1)
    np.testing.assert_array_equal(ref.position[:10], first.position[:10])  # t = 1 s: segment 2


def test_shipped_exercises_load_and_run() -> None:
    config = load_config()
    book = load_book(exercises_path(config), config.joints)
    assert {"reach_and_return", "shoulder_abduction", "elbow_flexion_extension"} <= \
        set(book.exercises)
    assert book.session("upper_limb")[0].exercise == "reach_and_return"
    for name in book.exercises:
        ref = build_reference(config.replace({"exercise.name": name}))
        np.testing.assert_allclose(ref.position[0], book.exercises[name].points[0])
        np.testing.assert_allclose(ref.position[-1], book.exercises[name].points[-1],
                                   atol=1e-12)


def test_unknown_exercise_is_named() -> None:
    config = load_config(None, {"exercise.name": "juggling"})
    with pytest.raises(ConfigError, match=r"unknown exercise 'juggling'.*reach_and_return"):
        build_reference(config)
    with pytest.raises(ConfigError, match=r"exercise\.name"):
        load_config(None, {"exercise.name": "a b"})


@pytest.mark.parametrize(("body", "match"), [
    ("exercises:\n  x: {points: [[0, 0, 0]], durations: []}\n", "x.points: must be at least 2"),
    ("exercises:\n  x: {points: [[0, 0, 0], [1, 1, 1]], durations: [1, 2]}\n",
     "x.durations: must have one entry per segment"),
    ("exercises:\n  x: {points: [[0, 0], [1, 1]], durations: [1]}\n", "x.points"),
    ("exercises:\n  x: {points: [[0, 0, 0], [1, 1, 1]], durations: [0]}\n", "must be > 0"),
    ("exercises:\n  x: {points: [[0, 0, 0], [1, 1, 1]], durations: [1]}\n"
     "sessions:\n  s: [{exercise: y, trials: 3}]\n", r"s\[1\].exercise: unknown exercise 'y'"),
    ("exercises:\n  x: {points: [[0, 0, 0], [1, 1, 1]], durations: [1]}\n"
     "sessions:\n  s: [{exercise: x, trials: 0}]\n", r"trials: must be an integer >= 1"),
    ("exercises: [1, 2]\n", "must hold a mapping"),
])
def test_bad_exercise_files_are_refused(tmp_path: Path, body: str, match: str) -> None:
    path = tmp_path / "ex.yaml"
    path.write_text(body)
    with pytest.raises(ConfigError, match=match) as info:
        load_book(path, 3)
    assert str(path) in str(info.value)


def test_segment_not_a_whole_number_of_periods(tmp_path: Path) -> None:
    path = tmp_path / "ex.yaml"
    path.write_text("exercises:\n  x: {points: [[0, 0, 0], [1, 1, 1]], durations: [1.005]}\n")
    config = load_config(None, {"exercise.name": "x", "exercise.file": str(path)})
    with pytest.raises(ConfigError, match="whole number of control periods"):
        build_reference(config)
