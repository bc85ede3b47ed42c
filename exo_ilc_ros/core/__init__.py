"""The paper's mathematics, ROS-free: arm model, reference, ILC laws, the learning session (the
in-process runner, and the logic the supervisor node runs) and its store. Nothing here imports
rclpy.

The code lives in rooms by concern, each importing only the rooms below it (the order of
:data:`ROOMS`; ``test/test_layers.py`` keeps it so). This face names what a user or a node
needs and loads it on first use (PEP 562), so ``import exo_ilc_ros.core`` costs nothing and a
reader of bags never loads numba.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .. import load_public

ROOMS = ("params", "arm", "reference", "loop", "learning", "convergence", "sim", "person",
         "persistence", "session", "protocol", "programs", "population")
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

if TYPE_CHECKING:  # the names of _WHERE for type checkers and editors (test_typed_face.py)
    from .arm.build import build_arm as build_arm
    from .arm.model import ArmModel as ArmModel
    from .convergence.bound import (
        IterationsToBound as IterationsToBound,
    )
    from .convergence.bound import (
        iterations_to_bound as iterations_to_bound,
    )
    from .convergence.factors import LoopAnalysis as LoopAnalysis
    from .convergence.factors import analyze_loop as analyze_loop
    from .convergence.growth import GrowthFit as GrowthFit
    from .convergence.growth import fit_growth as fit_growth
    from .errors import (
        ConfigError as ConfigError,
    )
    from .errors import (
        ExoIlcError as ExoIlcError,
    )
    from .errors import (
        ModelError as ModelError,
    )
    from .errors import (
        SafetyError as SafetyError,
    )
    from .errors import (
        StoreError as StoreError,
    )
    from .learning.factory import build_law as build_law
    from .learning.laws import (
        ErrorSum as ErrorSum,
    )
    from .learning.laws import (
        FeedforwardUpdate as FeedforwardUpdate,
    )
    from .learning.laws import (
        InitialFeedforward as InitialFeedforward,
    )
    from .learning.laws import (
        LearningLaw as LearningLaw,
    )
    from .learning.laws import (
        LinearLaw as LinearLaw,
    )
    from .learning.laws import (
        Memory as Memory,
    )
    from .learning.laws import (
        ScheduleIndex as ScheduleIndex,
    )
    from .learning.laws import (
        SignLaw as SignLaw,
    )
    from .learning.laws import (
        StepSchedule as StepSchedule,
    )
    from .learning.laws import (
        error_sums as error_sums,
    )
    from .learning.laws import (
        sgn as sgn,
    )
    from .learning.norm_optimal import NormOptimalLaw as NormOptimalLaw
    from .learning.norm_optimal_model import learning_matrices as learning_matrices
    from .learning.qfilter import QFilter as QFilter
    from .learning.qfilter import QFilteredLaw as QFilteredLaw
    from .loop.plant import PlantDynamics as PlantDynamics
    from .loop.record import TrialRecord as TrialRecord
    from .params.config import (
        Config as Config,
    )
    from .params.config import (
        config_dir as config_dir,
    )
    from .params.config import (
        default_config_path as default_config_path,
    )
    from .params.config import (
        load_config as load_config,
    )
    from .persistence.store import RunStore as RunStore
    from .reference.build import build_reference as build_reference
    from .reference.trajectory import (
        QuinticTrajectory as QuinticTrajectory,
    )
    from .reference.trajectory import (
        SampledReference as SampledReference,
    )
    from .session.learning_session import (
        LearningSession as LearningSession,
    )
    from .session.learning_session import (
        TrialConclusion as TrialConclusion,
    )
    from .session.learning_session import (
        run_trials as run_trials,
    )
    from .session.result import RunResult as RunResult
    from .session.result import StopReason as StopReason
    from .sim.experiment import Experiment as Experiment

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    """Load a public name's module on first use (PEP 562)."""
    return load_public(__name__, _WHERE, name, globals())


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
