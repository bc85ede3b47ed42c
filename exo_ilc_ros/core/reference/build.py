"""The reference a config describes: the paper's quintic of eq (14), or an exercise."""

from __future__ import annotations

from ..params.config import Config
from .exercise import exercise_reference
from .trajectory import QuinticTrajectory, SampledReference


def build_reference(config: Config) -> SampledReference:
    """The quintic reference of eq (14) sampled at the control period, or the config's
    exercise (``exercise.name``, a piecewise quintic through rest points, :mod:`.exercise`)."""

    exercise = exercise_reference(config)
    if exercise is not None:
        return exercise
    trajectory = QuinticTrajectory.rest_to_rest(config["trajectory.start"],
                                                config["trajectory.goal"],
                                                config["trajectory.duration"])
    return SampledReference.from_trajectory(trajectory, config["control.period"])
