"""What :mod:`.tuning` searches: the sign law's step schedules, eqs (22)-(24), per joint and
term (M, M', M''), parametrised so that every sample satisfies the schema's rules, or
norm-optimal's input-change weight and model mass error; and the config values of a sample."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import optuna

from ..core.params.config import Config

TERMS = ("position", "velocity", "acceleration")
"""The three step schedules: M (by |s e|), M' (by |s e_dot|), M'' (by |s e_ddot|)."""


LEVELS = ("level_low", "level_mid", "level_high")


SCHEDULE_KEYS = ("threshold_low", "threshold_high", *LEVELS)


THRESHOLD_RANGES: Mapping[str, tuple[float, float]] = {
    "position": (1e-2, 1e2), "velocity": (1e-3, 1e1), "acceleration": (1e-3, 1e1)}
"""Log-uniform range of ``threshold_low`` per term (the paper's values lie well inside)."""


RATIO_RANGE = (1.2, 100.0)
"""Log-uniform range of ``threshold_high / threshold_low`` (> 1: thresholds always increase)."""


LEVEL_RANGES: Mapping[str, tuple[float, float]] = {
    "level_low": (1e-5, 1e-2), "level_mid": (1e-4, 0.1), "level_high": (1e-3, 1.0)}
"""Log-uniform range of each step level (the paper's 0.001 ... 0.9 lie inside)."""


SPACE_VERSION = 1
"""Bumped whenever the search space changes (part of the default study name)."""


NORM_OPTIMAL_KEYS = ("norm_optimal.weight_input_change", "norm_optimal.model_mass_uncertainty")
"""What ``--law norm_optimal`` tunes: Wd per joint and the model's delta_m."""


INPUT_CHANGE_RANGE = (1e-12, 1e-4)
"""Log-uniform range of ``norm_optimal.weight_input_change`` (the shipped 1e-8 inside)."""


MODEL_DELTA_RANGE = (0.0, 0.2)
"""Uniform range of ``norm_optimal.model_mass_uncertainty``."""


def _name(term: str, joint: int, key: str) -> str:
    return f"{term}.j{joint + 1}.{key}"


def suggest_schedules(trial: optuna.Trial, joints: int) -> dict[str, list[float]]:
    """Sample every schedule value (dotted config names) within the schema's rules."""
    values: dict[str, list[float]] = {}
    for term in TERMS:
        columns: dict[str, list[float]] = {key: [] for key in SCHEDULE_KEYS}
        for j in range(joints):
            low = trial.suggest_float(_name(term, j, "threshold_low"),
                                      *THRESHOLD_RANGES[term], log=True)
            ratio = trial.suggest_float(_name(term, j, "threshold_ratio"), *RATIO_RANGE,
                                        log=True)
            columns["threshold_low"].append(low)
            columns["threshold_high"].append(low * ratio)
            for level in LEVELS:
                columns[level].append(trial.suggest_float(_name(term, j, level),
                                                          *LEVEL_RANGES[level], log=True))
        values.update({f"schedule.{term}.{key}": col for key, col in columns.items()})
    return values


def schedule_params(config: Config) -> dict[str, float]:
    """Optuna parameters that reproduce ``config``'s schedules (to enqueue them as a trial)."""
    params: dict[str, float] = {}
    for term in TERMS:
        base = f"schedule.{term}."
        for j in range(config.joints):
            low = config[base + "threshold_low"][j]
            params[_name(term, j, "threshold_low")] = low
            params[_name(term, j, "threshold_ratio")] = config[base + "threshold_high"][j] / low
            for level in LEVELS:
                params[_name(term, j, level)] = config[base + level][j]
    return params


def schedules_from_params(params: Mapping[str, float], joints: int) -> dict[str, list[float]]:
    """Config values (dotted names) of a trial's parameters (inverse of :func:`schedule_params`)."""
    values: dict[str, list[float]] = {}
    for term in TERMS:
        lows = [float(params[_name(term, j, "threshold_low")]) for j in range(joints)]
        ratios = [float(params[_name(term, j, "threshold_ratio")]) for j in range(joints)]
        values[f"schedule.{term}.threshold_low"] = lows
        values[f"schedule.{term}.threshold_high"] = [lo * r for lo, r in zip(lows, ratios,
                                                                               strict=True)]
        for level in LEVELS:
            values[f"schedule.{term}.{level}"] = [float(params[_name(term, j, level)])
                                                  for j in range(joints)]
    return values


def schedule_values(config: Config) -> dict[str, list[float]]:
    """The schedule part of a config (dotted names)."""
    return {f"schedule.{t}.{k}": config[f"schedule.{t}.{k}"] for t in TERMS for k in SCHEDULE_KEYS}


def suggest_weights(trial: optuna.Trial, joints: int) -> dict[str, Any]:
    """Sample the norm-optimal law's tuned values (:data:`NORM_OPTIMAL_KEYS`)."""
    change = [trial.suggest_float(f"norm_optimal.j{j + 1}.weight_input_change",
                                  *INPUT_CHANGE_RANGE, log=True) for j in range(joints)]
    delta = trial.suggest_float("norm_optimal.model_mass_uncertainty", *MODEL_DELTA_RANGE)
    return {NORM_OPTIMAL_KEYS[0]: change, NORM_OPTIMAL_KEYS[1]: delta}


def weight_params(config: Config) -> dict[str, float]:
    """Optuna parameters that reproduce ``config``'s norm-optimal tuned values."""
    params = {f"norm_optimal.j{j + 1}.weight_input_change": float(w)
              for j, w in enumerate(config[NORM_OPTIMAL_KEYS[0]])}
    params["norm_optimal.model_mass_uncertainty"] = float(config[NORM_OPTIMAL_KEYS[1]])
    return params


def weights_from_params(params: Mapping[str, float], joints: int) -> dict[str, Any]:
    """Config values of a trial's parameters (inverse of :func:`weight_params`)."""
    return {NORM_OPTIMAL_KEYS[0]: [float(params[f"norm_optimal.j{j + 1}.weight_input_change"])
                                   for j in range(joints)],
            NORM_OPTIMAL_KEYS[1]: float(params["norm_optimal.model_mass_uncertainty"])}


def tuned_values(config: Config, law: str) -> dict[str, Any]:
    """The part of ``config`` that ``law``'s tuning searches (dotted names)."""
    if law == "norm_optimal":
        return {k: config[k] for k in NORM_OPTIMAL_KEYS}
    return schedule_values(config)


def suggest(trial: optuna.Trial, joints: int, law: str) -> dict[str, Any]:
    if law == "norm_optimal":
        return suggest_weights(trial, joints)
    return suggest_schedules(trial, joints)


def space_params(config: Config, law: str) -> dict[str, float]:
    return weight_params(config) if law == "norm_optimal" else schedule_params(config)


def values_from_params(params: Mapping[str, float], joints: int, law: str) -> dict[str, Any]:
    if law == "norm_optimal":
        return weights_from_params(params, joints)
    return schedules_from_params(params, joints)
