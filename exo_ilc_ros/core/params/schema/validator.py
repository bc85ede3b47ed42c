"""The validator: a value coerced to its parameter's type and checked against its rule, and
the checks across parameters."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from ...errors import ConfigError
from ..hold_rule import hold_gain_problem, homing_gain_problem
from .key_groups import PATIENT_JOINTS, PERSON_SEGMENTS
from .parameter import Kind, Parameter
from .string_maps import _name_map_entries, parse_patient_joints


def coerce(param: Parameter, value: Any) -> Any:
    """``value`` converted to the parameter's type, or ConfigError naming the rule."""
    kind = param.kind
    if kind is Kind.DOUBLE:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(param.name, f"must be a number, got {value!r}")
        return float(value)
    if kind is Kind.INTEGER:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                return int(value)
            raise ConfigError(param.name, f"must be an integer, got {value!r}")
        return int(value)
    if kind is Kind.BOOL:
        if not isinstance(value, bool):
            raise ConfigError(param.name, f"must be true or false, got {value!r}")
        return value
    if kind is Kind.STRING:
        if param.choices and isinstance(value, int) and not isinstance(value, bool) \
                and str(value) in param.choices:
            return str(value)  # a choice YAML reads as a number: mas_grade: 2
        if not isinstance(value, str):
            raise ConfigError(param.name, f"must be a string, got {value!r}")
        return value
    if param.per_joint:
        broadcast = _per_joint_broadcast(param, value)
        if broadcast is not None:
            return broadcast  # per_joint_values() expands it once the joints are known
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise ConfigError(param.name, f"must be a list, got {value!r}")
    items = list(value)
    if kind is Kind.DOUBLE_ARRAY:
        if any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in items):
            raise ConfigError(param.name, f"must be a list of numbers, got {items!r}")
        return [float(v) for v in items]
    if any(not isinstance(v, str) for v in items):
        raise ConfigError(param.name, f"must be a list of strings, got {items!r}")
    return items


OTHER_JOINTS = "*"
"""In a per-joint name map, the entry for every joint the map does not name."""


def _per_joint_broadcast(param: Parameter, value: Any) -> float | str | dict[str, Any] | None:
    """A per-joint value given other than as a list, coerced: one value for every joint (a
    number; a string for a list of strings) or a map by joint name (a YAML mapping, or for a
    list of numbers the string 'name: value, name: value' ROS parameters can carry), with
    ``*`` for the joints it does not name. None: a list (coerced as one)."""
    numeric = param.kind is Kind.DOUBLE_ARRAY
    if numeric and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if not numeric and isinstance(value, str):
        return value
    entries: list[tuple[str, Any]]
    if isinstance(value, Mapping):
        entries = [(str(k), v) for k, v in value.items()]
    elif numeric and isinstance(value, str):
        form = "'joint_name: value' (a number)"
        if ":" not in value and "=" not in value:
            raise ConfigError(param.name, "must be a list, one value for every joint or a map "
                              f"by joint name ('joint_name: value, ...'), got {value!r}")
        entries = []
        for name, text in _name_map_entries(value, param.name, form):
            try:
                entries.append((name, float(text)))
            except ValueError:
                raise ConfigError(param.name, f"entry '{name}: {text}' is not {form}") from None
        if not entries:
            raise ConfigError(param.name, "must be a list, one value for every joint or a map "
                              "by joint name, got ''")
    else:
        return None
    out: dict[str, Any] = {}
    for name, item in entries:
        if numeric and (isinstance(item, bool) or not isinstance(item, (int, float))):
            raise ConfigError(param.name, f"joint {name!r}: must be a number, got {item!r}")
        if not numeric and not isinstance(item, str):
            raise ConfigError(param.name, f"joint {name!r}: must be a string, got {item!r}")
        out[name] = float(item) if numeric else item
    return out


def per_joint_values(param: Parameter, value: Any, joint_names: Sequence[str]) -> Any:
    """A coerced per-joint ``value`` as one entry per joint of ``joint_names`` (the arm's, or
    the patient's for a ``patient_joint`` key): a list as it is (its length is checked by
    :func:`check_value`), one value repeated for every joint, a map by joint name in the
    joints' order (``*`` for the joints it does not name). ConfigError naming the key: a map
    naming a joint that is not one of them, or leaving one out without ``*``."""
    if not param.per_joint or isinstance(value, list):
        return value
    if not isinstance(value, dict):
        return [value] * len(joint_names)
    whose = "the patient's" if param.patient_joint else "the arm's"
    unknown = [name for name in value if name != OTHER_JOINTS and name not in joint_names]
    if unknown:
        raise ConfigError(param.name, f"joint {unknown[0]!r} is not one of {whose} joints "
                          f"({', '.join(joint_names)})")
    missing = [name for name in joint_names if name not in value]
    if missing and OTHER_JOINTS not in value:
        raise ConfigError(param.name, f"the map by joint name leaves out {', '.join(missing)} "
                          f"(name every one of {whose} joints, or give '{OTHER_JOINTS}' for "
                          "the rest)")
    return [value.get(name, value.get(OTHER_JOINTS)) for name in joint_names]


def check_value(param: Parameter, value: Any, joints: int,
                joint_names: Sequence[str] = ()) -> None:
    """Raise ConfigError if an already coerced ``value`` breaks ``param``'s own rule (a
    per-joint value's error names the joint, from ``joint_names`` where given)."""
    numbers: list[float] = []
    if param.kind in (Kind.DOUBLE, Kind.INTEGER):
        numbers = [float(value)]
    elif param.kind is Kind.DOUBLE_ARRAY:
        numbers = list(value) if isinstance(value, list) else [float(value)]

    def fail(bad: Callable[[float], bool], rule: str) -> None:
        index = next((i for i, x in enumerate(numbers) if bad(x)), None)
        if index is None:
            return
        if param.per_joint and isinstance(value, list):
            name = joint_names[index] if index < len(joint_names) else str(index + 1)
            raise ConfigError(param.name, f"joint {name!r}: {rule}, got {numbers[index]!r}")
        raise ConfigError(param.name, f"{rule}, got {value!r}")

    fail(lambda x: not math.isfinite(x), "must be finite (no NaN or inf)")
    if param.per_joint and isinstance(value, list) and len(value) != joints:
        names = f": {', '.join(joint_names)}" if joint_names else ""
        whose = f" of the patient (the patient's joints: {PATIENT_JOINTS} maps them onto the " \
            "arm's)" if param.patient_joint else ""
        raise ConfigError(param.name, f"must have one entry per joint{whose} ({joints}{names}), "
                          "one value for every joint or a map by joint name, got "
                          f"{len(value)} entries")
    if param.minimum is not None:
        minimum = param.minimum
        fail(lambda x: x < minimum, f"must be >= {minimum:g}")
    if param.strictly_positive:
        fail(lambda x: x <= 0.0, "must be > 0")
    if param.choices and value not in param.choices:
        raise ConfigError(param.name, f"must be one of {', '.join(param.choices)}; got {value!r}")
    if param.extra_rule is not None:
        problem = param.extra_rule(value)
        if problem:
            raise ConfigError(param.name, problem)


def period_problem(period: float, step: float, duration: float) -> tuple[str, str] | None:
    """(key, rule) a control period breaks against the RK4 step and the trial's duration (the
    step must divide it, the trial be a whole number of it); None: it meets both. The schema's
    rule, and the one :mod:`exo_ilc_ros.core.loop.rate` picks a period by."""
    ratio = period / step
    if step > period or abs(ratio - round(ratio)) > 1e-9 * ratio:
        return "integration_step", \
            f"must divide control.period ({period:g} s) a whole number of times"
    steps = duration / period
    if abs(steps - round(steps)) > 1e-9 * max(steps, 1.0):
        return "trajectory.duration", f"must be a whole number of control periods ({period:g} s)"
    return None


def check_consistency(values: Mapping[str, Any]) -> None:
    """Rules between parameters: monotonic thresholds, a whole number of sub-steps, ..."""
    names = values["joint_names"]
    for term in ("position", "velocity", "acceleration"):
        low = values[f"schedule.{term}.threshold_low"]
        high = values[f"schedule.{term}.threshold_high"]
        for j, (lo, hi) in enumerate(zip(low, high, strict=True)):
            if not lo < hi:
                raise ConfigError(f"schedule.{term}.threshold_low",
                                  f"thresholds must increase: joint {names[j]!r} has "
                                  f"threshold_low {lo:g} >= threshold_high {hi:g}")
    period = values["control.period"]
    problem = period_problem(period, values["integration_step"], values["trajectory.duration"])
    if problem is not None:
        raise ConfigError(*problem)
    if values["model.source"] == "cones":
        _check_cones(values)
        if values["model.urdf_joint_dynamics"] != "ignore":
            raise ConfigError("model.urdf_joint_dynamics",
                              "a cone arm has no URDF <dynamics>: only with model.source urdf")
    elif not values["model.urdf"] or not values["model.base_link"] or \
            not values["model.tip_link"]:
        empty = next(k for k in ("model.urdf", "model.base_link", "model.tip_link")
                     if not values[k])
        raise ConfigError(empty, "model.source urdf needs the URDF file, its base link and its "
                          "tip link")
    nyquist = 0.5 / period
    if values["q_filter.cutoff_hz"] >= nyquist:
        raise ConfigError("q_filter.cutoff_hz",
                          f"must be below the Nyquist frequency {nyquist:g} Hz of "
                          f"control.period {period:g} s")
    if values["patient.spasticity.mas_grade"] != "custom":
        for key in ("stiffness", "damping", "reflex_gain", "reflex_threshold", "reflex_max"):
            if any(values[f"patient.spasticity.{key}"]):
                raise ConfigError(f"patient.spasticity.{key}",
                                  "give either a mas_grade (its preset) or the custom values, "
                                  "not both (set mas_grade: custom)")

    if values["person.drive.mas_grade"] != "custom":
        for key in ("tone", "length_threshold", "velocity_threshold", "length_gain",
                    "velocity_gain", "reflex_max"):
            if values[f"person.drive.{key}"]:
                raise ConfigError(f"person.drive.{key}", "give either a mas_grade (its preset) "
                                  "or the custom values, not both (set mas_grade: custom)")
    _check_person(values)
    hold = hold_gain_problem(values)
    if hold is not None:
        raise ConfigError(*hold)
    homing = homing_gain_problem(values)
    if homing is not None:
        raise ConfigError(*homing)
    if len(set(values["joint_names"])) != len(values["joint_names"]):
        raise ConfigError("joint_names", "joint names must be unique")
    if any(not name for name in values["joint_names"]):
        raise ConfigError("joint_names", "joint names must not be empty")


def _check_cones(values: Mapping[str, Any]) -> None:
    """The cone arm's rules (model.source: cones)."""
    masses = values["model.link_masses"]
    lengths = values["model.link_lengths"]
    radii = zip(values["model.radius_proximal"], values["model.radius_distal"], strict=True)
    for j, (m, length, (r1, r2)) in enumerate(zip(masses, lengths, radii, strict=True)):
        if m > 0.0 and length > 0.0 and r1 == 0.0 and r2 == 0.0:
            raise ConfigError("model.radius_proximal",
                              f"link {j + 1} ({values['joint_names'][j]!r}) has mass and "
                              "length, so it needs a positive radius")
    if all(m == 0.0 for m in masses):
        raise ConfigError("model.link_masses", "at least one link must have mass")


def check_patient_joints(values: Mapping[str, Any]) -> None:
    """Every arm joint ``patient.joints`` names is one of ``joint_names`` (checked once they
    are known to be the arm's: a URDF arm's after the URDF's)."""
    arm = list(values["joint_names"])
    for patient, (target, _) in parse_patient_joints(values[PATIENT_JOINTS]).items():
        if target not in arm:
            raise ConfigError(PATIENT_JOINTS, f"the patient's joint {patient!r} acts on "
                              f"{target!r}, which is not a joint of the arm ({', '.join(arm)})")


def _check_person(values: Mapping[str, Any]) -> None:
    """A person only on a URDF arm, each segment's sagittal axis normal to its direction."""
    if not values["person.enabled"]:
        return
    if values["model.source"] != "urdf":
        raise ConfigError("person.enabled", "the paper's arm (model.source cones) is the "
                          "person's arm itself: its links are the upper arm and forearm "
                          "(model.link_masses); a person's segments are added to a URDF "
                          "exoskeleton (model.source urdf)")
    linked = [s for s in PERSON_SEGMENTS if values[f"person.{s}.link"]]
    if not linked:
        raise ConfigError("person.enabled", "no segment is strapped to a link (give "
                          "person.upper_arm.link, person.forearm.link or person.hand.link)")
    for segment in linked:
        along = values[f"person.{segment}.direction"]
        axis = values[f"person.{segment}.sagittal_axis"]
        dot = sum(a * b for a, b in zip(along, axis, strict=True))
        norms = math.sqrt(sum(a * a for a in along) * sum(b * b for b in axis))
        if abs(dot) > 1e-9 * norms:
            raise ConfigError(f"person.{segment}.sagittal_axis", f"must be normal to "
                              f"person.{segment}.direction {along}, got {axis}")
