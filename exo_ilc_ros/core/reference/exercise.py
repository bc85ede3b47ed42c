"""Exercises: named movements a therapy session repeats, each a reference trajectory.

The paper's quintic of eq (14), from ``trajectory.*``, is the exercise :data:`PAPER_EXERCISE`
(the default). Any other exercise is defined in an exercises file (``exercise.file``; the
shipped ``config/exercises/default.yaml`` by default) by its *rest points* and the duration of
each movement between them::

    exercises:
      reach_and_return:
        description: reach forward and up, then back
        points: [[0.0, 0.0, 0.0], [1.2, 0.3, 0.8], [0.0, 0.0, 0.0]]   # rad, per joint
        durations: [2.5, 2.5]                                         # s, per segment

The reference is a piecewise quintic: between consecutive points the rest-to-rest quintic of
eq (14) (:meth:`.QuinticTrajectory.rest_to_rest`), so position, velocity and acceleration are
continuous everywhere and the arm is at rest (zero velocity and acceleration) at every point; a
via-point is a rest point. The same file names sessions, a list of exercises with the number of
trials (repetitions) of each::

    sessions:
      standard:
        - {exercise: reach_and_return, trials: 30}
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import ConfigError
from ..params.config import Config, config_dir
from .trajectory import QuinticTrajectory, SampledReference

PAPER_EXERCISE = "paper_quintic"
"""The exercise that is the paper's quintic, eq (14), from ``trajectory.*``."""
EXERCISES_FILE = "exercises/default.yaml"


@dataclass(frozen=True, eq=False)
class Exercise:
    """A movement through rest points: ``points`` (K+1, joints) rad, ``durations`` (K,) s."""

    name: str
    points: np.ndarray
    durations: np.ndarray
    description: str = ""

    @property
    def duration(self) -> float:
        """The whole movement (s)."""
        return float(np.sum(self.durations))

    def segments(self) -> list[QuinticTrajectory]:
        """The rest-to-rest quintic of eq (14) between consecutive points."""
        return [QuinticTrajectory.rest_to_rest(a, b, float(t)) for a, b, t in
                zip(self.points[:-1], self.points[1:], self.durations, strict=True)]

    def sample(self, period: float) -> SampledReference:
        """The piecewise quintic at t_i = i * period; every segment a whole number of periods
        (so every rest point is a sample)."""
        counts = []
        for k, t in enumerate(self.durations):
            steps = t / period
            n = int(round(steps))
            if n < 1 or abs(steps - n) > 1e-9 * max(1.0, steps):
                raise ConfigError(f"exercises.{self.name}.durations",
                                  f"segment {k + 1} ({t:g} s) must be a whole number of control "
                                  f"periods ({period:g} s)")
            counts.append(n)
        total = sum(counts)
        time = np.arange(total + 1) * period
        dof = self.points.shape[1]
        q, qd, qdd = (np.empty((total + 1, dof)) for _ in range(3))
        first = 0
        for segment, n in zip(self.segments(), counts, strict=True):
            local = np.arange(n + 1) * period  # the segment's own clock: rest points are exact
            sq, sqd, sqdd = segment.evaluate(local)
            q[first:first + n + 1], qd[first:first + n + 1], qdd[first:first + n + 1] = \
                sq, sqd, sqdd
            first += n
        return SampledReference(time, q, qd, qdd, float(period))


@dataclass(frozen=True)
class SessionItem:
    """One exercise of a session and how many trials (repetitions) it gets."""

    exercise: str
    trials: int


@dataclass(frozen=True)
class ExerciseBook:
    """The exercises and sessions of one exercises file."""

    path: Path
    exercises: dict[str, Exercise]
    sessions: dict[str, list[SessionItem]]

    def exercise(self, name: str) -> Exercise:
        """The exercise ``name``; ConfigError naming it and the file when unknown."""
        if name not in self.exercises:
            raise ConfigError("exercise.name", f"unknown exercise {name!r}; {self.path} defines "
                              + ", ".join([PAPER_EXERCISE, *sorted(self.exercises)]))
        return self.exercises[name]

    def session(self, name: str) -> list[SessionItem]:
        """The session plan ``name``; ConfigError naming it and the file when unknown."""
        if name not in self.sessions:
            raise ConfigError("session", f"unknown session {name!r}; {self.path} defines "
                              + (", ".join(sorted(self.sessions)) or "none"))
        return self.sessions[name]


def exercises_path(config: Config) -> Path:
    """The exercises file of the config (``exercise.file``, or the shipped one)."""
    given = config["exercise.file"]
    return Path(given) if given else config_dir() / EXERCISES_FILE


def load_book(path: Path | str, joints: int) -> ExerciseBook:
    """The exercises file at ``path``, checked: every point has ``joints`` finite values, one
    duration > 0 per segment, every session item names a known exercise with trials >= 1."""
    path = Path(path)
    source = str(path)
    try:
        document = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigError("exercise.file", f"cannot read: {exc.strerror}", source) from None
    except yaml.YAMLError as exc:
        raise ConfigError("exercise.file", f"invalid YAML: {exc}", source) from None
    if not isinstance(document, dict) or not isinstance(document.get("exercises"), dict):
        raise ConfigError("exercises", "the file must hold a mapping 'exercises: {name: ...}'",
                          source)
    exercises = {str(name): _exercise(str(name), body, joints, source)
                 for name, body in document["exercises"].items()}
    if PAPER_EXERCISE in exercises:
        raise ConfigError(f"exercises.{PAPER_EXERCISE}", "is reserved for the paper's quintic "
                          "(trajectory.*)", source)
    sessions: dict[str, list[SessionItem]] = {}
    for name, items in (document.get("sessions") or {}).items():
        key = f"sessions.{name}"
        if not isinstance(items, list) or not items:
            raise ConfigError(key, "must be a non-empty list of {exercise, trials}", source)
        plan = []
        for i, item in enumerate(items, start=1):
            if not isinstance(item, dict) or set(item) != {"exercise", "trials"}:
                raise ConfigError(f"{key}[{i}]", "must be {exercise: NAME, trials: N}", source)
            exercise, trials = str(item["exercise"]), item["trials"]
            if exercise != PAPER_EXERCISE and exercise not in exercises:
                raise ConfigError(f"{key}[{i}].exercise", f"unknown exercise {exercise!r}",
                                  source)
            if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
                raise ConfigError(f"{key}[{i}].trials", f"must be an integer >= 1, got "
                                  f"{trials!r}", source)
            plan.append(SessionItem(exercise, trials))
        sessions[str(name)] = plan
    return ExerciseBook(path, exercises, sessions)


def _exercise(name: str, body: Any, joints: int, source: str) -> Exercise:
    key = f"exercises.{name}"
    if not isinstance(body, dict) or not {"points", "durations"} <= set(body):
        raise ConfigError(key, "must have points (rad, one row per rest point) and durations "
                          "(s, one per segment)", source)
    try:
        points = np.asarray(body["points"], dtype=float)
        durations = np.asarray(body["durations"], dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(key, "points and durations must be numbers", source) from None
    if points.ndim != 2 or points.shape[0] < 2 or points.shape[1] != joints:
        raise ConfigError(f"{key}.points", f"must be at least 2 rows of {joints} joint angles "
                          f"(rad), got shape {points.shape}", source)
    if durations.shape[0] != points.shape[0] - 1:
        raise ConfigError(f"{key}.durations", f"must have one entry per segment "
                          f"({points.shape[0] - 1}), got {durations.shape[0]}", source)
    if not (np.all(np.isfinite(points)) and np.all(np.isfinite(durations))):
        raise ConfigError(key, "must be finite (no NaN or inf)", source)
    if np.any(durations <= 0.0):
        raise ConfigError(f"{key}.durations", "must be > 0", source)
    return Exercise(name, points, durations, str(body.get("description", "")))


def exercise_reference(config: Config) -> SampledReference | None:
    """The sampled reference of the config's ``exercise.name`` (None for the paper's quintic,
    which ``trajectory.*`` defines)."""
    name = config["exercise.name"]
    if name == PAPER_EXERCISE:
        return None
    book = load_book(exercises_path(config), config.joints)
    return book.exercise(name).sample(float(config["control.period"]))


def exercise_duration(config: Config) -> float:
    """The duration (s) of the config's exercise."""
    if config["exercise.name"] == PAPER_EXERCISE:
        return float(config["trajectory.duration"])
    book = load_book(exercises_path(config), config.joints)
    return book.exercise(config["exercise.name"]).duration

