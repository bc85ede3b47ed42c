"""The paper's mathematics, ROS-free: arm model, reference, ILC laws, the learning session (the
in-process runner, and the logic the supervisor node runs) and its store. Nothing here imports
rclpy.

The code lives in rooms by concern, each importing only the rooms below it (the order of
:data:`ROOMS`; ``test/test_layers.py`` keeps it so). This face names what a user or a node
needs and loads it on first use (PEP 562), so ``import exo_ilc_ros.core`` costs nothing and a
reader of bags never loads numba.
"""

from __future__ import annotations

from typing import Any

from .. import load_public

ROOMS = ("params", "arm", "reference", "loop", "learning", "convergence", "sim", "persistence",
         "session", "protocol", "programs", "population")
"""core's subpackages, bottom first: each may import only those before it (and the shared
modules ``errors`` and ``_numba_cache``)."""

_WHERE = {
    "build_arm": ".arm.build",
    "ArmModel": ".arm.model",
    "IterationsToBound": ".convergence.bound",
    "iterations_to_bound": ".convergence.bound",
    "LoopAnalysis": ".convergence.factors",
    "analyze_loop": ".convergence.factors",
    "GrowthFit": ".convergence.growth",
    "fit_growth": ".convergence.growth",
    "ConfigError": ".errors",
    "ExoIlcError": ".errors",
    "ModelError": ".errors",
    "SafetyError": ".errors",
    "StoreError": ".errors",
    "build_law": ".learning.factory",
    "ErrorSum": ".learning.laws",
    "FeedforwardUpdate": ".learning.laws",
    "InitialFeedforward": ".learning.laws",
    "LearningLaw": ".learning.laws",
    "LinearLaw": ".learning.laws",
    "Memory": ".learning.laws",
    "ScheduleIndex": ".learning.laws",
    "SignLaw": ".learning.laws",
    "StepSchedule": ".learning.laws",
    "error_sums": ".learning.laws",
    "sgn": ".learning.laws",
    "NormOptimalLaw": ".learning.norm_optimal",
    "learning_matrices": ".learning.norm_optimal_model",
    "QFilter": ".learning.qfilter",
    "QFilteredLaw": ".learning.qfilter",
    "PlantDynamics": ".loop.plant",
    "TrialRecord": ".loop.record",
    "Config": ".params.config",
    "config_dir": ".params.config",
    "default_config_path": ".params.config",
    "load_config": ".params.config",
    "RunStore": ".persistence.store",
    "build_reference": ".reference.build",
    "QuinticTrajectory": ".reference.trajectory",
    "SampledReference": ".reference.trajectory",
    "LearningSession": ".session.learning_session",
    "RunResult": ".session.result",
    "StopReason": ".session.result",
    "TrialConclusion": ".session.learning_session",
    "run_trials": ".session.learning_session",
    "Experiment": ".sim.experiment",
}
"""Public name -> the module that defines it."""

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    """Load a public name's module on first use (PEP 562)."""
    return load_public(__name__, _WHERE, name, globals())


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
