"""The rule functions of the schema's parameters (each an ``extra_rule``: a problem, or None)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ...errors import ConfigError
from .key_groups import AXIS_VECTORS
from .string_maps import parse_locked_joints, parse_patient_joints


def _parse_problem(parse: Callable[[str], object]) -> Callable[[Any], str | None]:
    """An ``extra_rule`` from a parser: its ConfigError's rule, or None when it parses."""
    def problem(value: Any) -> str | None:
        try:
            parse(value)
        except ConfigError as exc:
            return exc.rule
        return None
    return problem


_locks_problem = _parse_problem(parse_locked_joints)
_patient_joints_problem = _parse_problem(parse_patient_joints)


def _vector_rule(value: Any) -> str | None:
    return None if len(value) == 3 else f"must be [x, y, z] (3 numbers), got {value!r}"


def _direction_rule(value: Any) -> str | None:
    if len(value) != 3:
        return _vector_rule(value)
    return None if any(value) else "must not be zero (a direction)"


def _axes_rule(value: Any) -> str | None:
    bad = [v for v in value if v not in AXIS_VECTORS]
    return f"unknown joint axis {bad[0]!r}; use one of {sorted(AXIS_VECTORS)}" if bad else None


def _range_rule(value: Any) -> str | None:
    if len(value) != 2 or value[0] > value[1]:
        return f"must be [low, high] with low <= high, got {value!r}"
    return None


def _margin_rule(value: Any) -> str | None:
    return None if value < 1.0 else f"must be < 1 (a share of the limit), got {value!r}"


def _priority_rule(value: Any) -> str | None:
    return None if value <= 99 else f"must be 0..99 (SCHED_FIFO priorities), got {value!r}"


def _forgetting_rule(value: Any) -> str | None:
    return None if 0.0 < value <= 1.0 else f"must be in (0, 1] (1: no forgetting), got {value!r}"


def _averaging_memory_rule(value: Any) -> str | None:
    return None if value == 0.0 or value >= 2.0 else \
        f"must be 0 (off) or >= 2 trials (lambda = 1 - 1 / memory), got {value!r}"


def _node_name_rule(value: Any) -> str | None:
    ok = bool(value) and not value[0].isdigit() and all(c.isalnum() or c == "_" for c in value)
    return None if ok else f"must be a ROS node name (letters, digits and _), got {value!r}"


def _name_rule(value: Any) -> str | None:
    ok = bool(value) and all(c.isalnum() or c in "_-" for c in value)
    return None if ok else f"must be a name of letters, digits, _ and -, got {value!r}"


MAS_GRADES = ("custom", "0", "1", "1+", "2", "3")
"""``patient.spasticity.mas_grade``: ``custom`` (the spasticity values given) or a Modified
Ashworth grade (its preset, core/loop/patient.py ``MAS_PRESETS``)."""


def _fraction_rule(value: Any) -> str | None:
    return None if value <= 1.0 else f"must be <= 1 (a share of the gain), got {value!r}"


def _retention_rule(value: Any) -> str | None:
    return None if value <= 1.0 else f"must be <= 1 (a share kept per trial), got {value!r}"


def _pole_rule(value: Any) -> str | None:
    return None if value <= 1.0 else f"must be <= 1 (a pole's radius; 1: off), got {value!r}"


def _share_rule(value: Any) -> str | None:
    return None if value <= 1.0 else f"must be <= 1 (a share of the periods), got {value!r}"
