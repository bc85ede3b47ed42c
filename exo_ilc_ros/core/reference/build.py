"""The reference a config describes: the paper's quintic of eq (14), or an exercise; for a URDF
arm checked against the URDF's position and velocity limits."""

from __future__ import annotations

from ..arm.build import urdf_chain
from ..arm.urdf_chain import check_reference_limits
from ..params.config import Config
from .exercise import PAPER_EXERCISE, exercise_reference
from .trajectory import QuinticTrajectory, SampledReference


def build_reference(config: Config) -> SampledReference:
    """The quintic reference of eq (14) sampled at the control period, or the config's
    exercise (``exercise.name``, a piecewise quintic through rest points, :mod:`.exercise`).
    A URDF arm's reference must stay within its joints' ``<limit lower upper velocity>``
    (:class:`~exo_ilc_ros.core.arm.urdf_chain.LimitError` naming the joint, time and value)."""

    reference = exercise_reference(config)
    if reference is None:
        trajectory = QuinticTrajectory.rest_to_rest(config["trajectory.start"],
                                                    config["trajectory.goal"],
                                                    config["trajectory.duration"])
        reference = SampledReference.from_trajectory(trajectory, config["control.period"])
    if config["model.source"] == "urdf":
        name = config["exercise.name"]
        what = "the reference (trajectory.start/goal/duration)" if name == PAPER_EXERCISE \
            else f"exercise {name!r}"
        check_reference_limits(urdf_chain(config), reference.time, reference.position,
                               reference.velocity, what)
    return reference
