"""The trial protocol's messages as ilc_supervisor sends them (rclpy objects; key-values from
:mod:`exo_ilc_ros.wire.protocol`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticStatus
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ..core.params.schema import SUPERVISOR
from ..core.person.cuffs import cuff_summary_values
from ..core.programs.identified import Identified
from ..core.programs.metrics import metric_summary_values
from ..core.reference.trajectory import SampledReference
from ..core.session.learning_session import TrialConclusion
from ..wire import topics
from ..wire.protocol import feedforward_frame, key_values, summary_values
from ..wire.trial_metrics import trial_metrics
from .diagnostics import doubles, status


def feedforward_message(reference: SampledReference, feedforward: np.ndarray, trial: int,
                        t0_ns: int, step_ns: int, joint_names: Sequence[str],
                        joint_force: np.ndarray | None = None) -> JointTrajectory:
    """``/ilc/feedforward`` of trial ``trial`` starting at ``t0_ns``: frame ``trial:<k>``, one
    point per sample (positions, velocities: the reference; accelerations: u_ff; effort: the
    identified joint forces computed torque adds, N m, empty when none)."""
    msg = JointTrajectory()
    msg.header.frame_id = feedforward_frame(trial)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t0_ns, 1_000_000_000)
    msg.joint_names = list(joint_names)
    points = []
    for i in range(reference.samples):
        sec, nanosec = divmod(i * step_ns, 1_000_000_000)
        points.append(JointTrajectoryPoint(
            positions=doubles(reference.position[i]), velocities=doubles(reference.velocity[i]),
            accelerations=doubles(feedforward[i]),
            effort=[] if joint_force is None else doubles(joint_force[i]),
            time_from_start=Duration(sec=sec, nanosec=nanosec)))
    msg.points = points
    return msg


def trial_summary(conclusion: TrialConclusion, joint_names: Sequence[str]) -> DiagnosticStatus:
    """``/ilc/trial_summary`` of a concluded trial: OK within the bound, else WARN; with the
    identified patient (``identified/...``) when the session identifies it, and the cuff
    metrics (``cuff/<cuff>/<metric>``) when a person is strapped in."""
    record, config = conclusion.record, conclusion.config
    values = summary_values(record.trial, config["mass_uncertainty"], config["law"],
                            joint_names, record.max_abs_error,
                            np.max(np.abs(record.feedforward), axis=0),
                            np.max(np.abs(record.effort), axis=0), record.levels,
                            record.aborted_at, conclusion.applied,
                            None if record.true_position is None
                            else record.true_max_abs_error,
                            conclusion.update.notes if conclusion.learned else ())
    values += metric_summary_values(record, config, joint_names)  # core/programs/metrics.py
    values += cuff_summary_values(record.cuff_wrench)  # a person strapped in (core/person/)
    if conclusion.joint_forces is not None:  # core/programs/identified.py
        values += Identified.from_step(conclusion.joint_forces, joint_names).summary_values()
    level = DiagnosticStatus.OK if conclusion.within_bound else DiagnosticStatus.WARN
    return status(topics.SUMMARY_STATUS, f"trial {record.trial}", values, level, SUPERVISOR)


def trial_metrics_message(summary: DiagnosticStatus,
                          joint_names: Sequence[str]) -> Float64MultiArray:
    """``/ilc/trial_metrics`` of a trial summary status (:mod:`exo_ilc_ros.wire.trial_metrics`)."""
    array = trial_metrics(key_values(summary), joint_names,
                          summary.level != DiagnosticStatus.OK)
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=d.label, size=d.size, stride=d.stride)
                      for d in array.dims]
    msg.layout.data_offset = array.data_offset
    msg.data = doubles(np.asarray(array.data, dtype=float))
    return msg
