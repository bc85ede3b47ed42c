"""The paper's mathematics, ROS-free: arm model, reference, computed torque, ILC laws, integrator
and an in-process trial runner. Nothing here imports rclpy."""

from __future__ import annotations

from . import _numba_cache  # noqa: F401  (must run before the kernels are compiled)
from .config import Config, config_dir, default_config_path, load_config
from .convergence import LoopAnalysis, analyze_loop
from .errors import ConfigError, ExoIlcError, ModelError
from .experiment import (
    Experiment,
    IterationsToBound,
    build_arm,
    build_law,
    build_reference,
    iterations_to_bound,
)
from .growth import GrowthFit, fit_growth
from .integrator import (
    PlantDynamics,
    computed_torque_kernel,
    feedback_input,
    integrate_period,
    simulate_trial,
)
from .laws import (
    ErrorSum,
    FeedforwardUpdate,
    InitialFeedforward,
    LearningLaw,
    LinearLaw,
    Memory,
    ScheduleIndex,
    SignLaw,
    StepSchedule,
    TrialRecord,
    error_sums,
    sgn,
)
from .model import ArmModel
from .norm_optimal import NormOptimalLaw, learning_matrices
from .qfilter import QFilter, QFilteredLaw
from .session import LearningSession, RunResult, StopReason, TrialConclusion, run_trials
from .trajectory import QuinticTrajectory, SampledReference

__all__ = [
    "ArmModel", "Config", "ConfigError", "ErrorSum", "ExoIlcError", "Experiment",
    "FeedforwardUpdate", "GrowthFit", "InitialFeedforward", "IterationsToBound", "LearningLaw",
    "LearningSession", "LinearLaw", "LoopAnalysis", "Memory", "ModelError", "NormOptimalLaw",
    "PlantDynamics",
    "QFilter", "QFilteredLaw", "QuinticTrajectory", "RunResult", "SampledReference",
    "ScheduleIndex", "SignLaw", "StepSchedule", "StopReason", "TrialConclusion", "TrialRecord",
    "analyze_loop", "build_arm", "build_law", "build_reference", "computed_torque_kernel",
    "config_dir", "default_config_path", "error_sums", "feedback_input", "fit_growth",
    "integrate_period", "iterations_to_bound", "learning_matrices", "load_config", "run_trials",
    "sgn", "simulate_trial",
]
