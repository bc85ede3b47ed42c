"""The paper's mathematics, ROS-free: arm model, reference, ILC laws, the learning session (the
in-process runner, and the logic the supervisor node runs) and its store. Nothing here imports
rclpy.

What a user or a node needs is importable from here. The compiled kernels live in their own
modules, by role: :mod:`.plant` (RK4 with ZOH effort, eq (8); the effort clamp and saturation),
:mod:`.controller` (PD eq (11), computed torque eqs (9)/(16), error envelope, safe hold) and
:mod:`.trial` (one trial in-process, a graph trial rebuilt from its samples).
"""

from __future__ import annotations

from . import _numba_cache  # noqa: F401  (must run before the kernels are compiled)
from .config import Config, config_dir, default_config_path, load_config
from .convergence import LoopAnalysis, analyze_loop
from .errors import ConfigError, ExoIlcError, ModelError, SafetyError, StoreError
from .experiment import (
    Experiment,
    IterationsToBound,
    build_arm,
    build_law,
    build_reference,
    iterations_to_bound,
)
from .growth import GrowthFit, fit_growth
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
from .plant import PlantDynamics
from .qfilter import QFilter, QFilteredLaw
from .session import LearningSession, RunResult, StopReason, TrialConclusion, run_trials
from .store import RunStore
from .trajectory import QuinticTrajectory, SampledReference

__all__ = [
    "ArmModel", "Config", "ConfigError", "ErrorSum", "ExoIlcError", "Experiment",
    "FeedforwardUpdate", "GrowthFit", "InitialFeedforward", "IterationsToBound", "LearningLaw",
    "LearningSession", "LinearLaw", "LoopAnalysis", "Memory", "ModelError", "NormOptimalLaw",
    "PlantDynamics", "QFilter", "QFilteredLaw", "QuinticTrajectory", "RunResult", "RunStore",
    "SafetyError", "SampledReference", "ScheduleIndex", "SignLaw", "StepSchedule", "StopReason",
    "StoreError", "TrialConclusion", "TrialRecord", "analyze_loop", "build_arm", "build_law",
    "build_reference", "config_dir", "default_config_path", "error_sums", "fit_growth",
    "iterations_to_bound", "learning_matrices", "load_config", "run_trials", "sgn",
]
