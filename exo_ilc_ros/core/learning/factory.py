"""The learning law a config names (``law``), with its options, assist-as-needed and the
Q-filter: the one place a law is built from parameters."""

from __future__ import annotations

import numpy as np

from ..params.config import Config
from .assist import with_assist
from .laws import (
    ErrorSum,
    InitialFeedforward,
    LearningLaw,
    LinearLaw,
    Memory,
    ScheduleIndex,
    SignLaw,
    StepSchedule,
)
from .norm_optimal import NormOptimalLaw
from .norm_optimal_model import PatientLinearisation
from .qfilter import QFilteredLaw, feedforward_limit_of, qfilter_of


def build_schedule(config: Config, term: str) -> StepSchedule:
    """The step function of ``term`` (position, velocity or acceleration), eqs (22)-(24)."""
    base = f"schedule.{term}."
    return StepSchedule.from_values(*(config[base + k] for k in (
        "threshold_low", "threshold_high", "level_low", "level_mid", "level_high")))


def build_law(config: Config, law: str | None = None,
              patient: PatientLinearisation | None = None) -> LearningLaw:
    """The learning law named by ``law`` (default: the config's ``law``) with its options
    (norm-optimal's model about the identified ``patient`` when given),
    with assist-as-needed when the config enables it (:mod:`.assist`), wrapped in
    :class:`QFilteredLaw` when the config enables the Q-filter or a
    ``feedforward_limit``."""
    inner = with_assist(_build_plain_law(config, law, patient), config)
    qfilter = qfilter_of(config)
    limit = feedforward_limit_of(config)
    if qfilter is None and limit is None:
        return inner
    return QFilteredLaw(inner, qfilter, limit)


def _build_plain_law(config: Config, law: str | None,
                     patient: PatientLinearisation | None = None) -> LearningLaw:
    name = law or config["law"]
    memory = Memory(config["memory"])
    initial = InitialFeedforward(config["initial_feedforward"])
    if name == "sign":
        return SignLaw(build_schedule(config, "position"), build_schedule(config, "velocity"),
                       build_schedule(config, "acceleration"), memory,
                       ScheduleIndex(config["schedule_index"]), ErrorSum(config["error_sum"]),
                       initial)
    if name == "linear":
        return LinearLaw(np.asarray(config["linear.gain_position"]),
                         np.asarray(config["linear.gain_velocity"]),
                         np.asarray(config["linear.gain_acceleration"]), memory, initial)
    if name == "norm_optimal":
        return NormOptimalLaw.from_config(config, patient)
    raise ValueError(f"unknown law {name!r}; use sign, linear or norm_optimal")
