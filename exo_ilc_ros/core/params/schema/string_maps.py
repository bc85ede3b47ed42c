"""The string-map parsers of the schema (``name: value, name: value`` parameters:
``model.locked_joints``, ``patient.joints``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ...errors import ConfigError
from .key_groups import PATIENT_JOINTS


def _name_map_entries(text: str, key: str, form: str) -> list[tuple[str, str]]:
    """('name', 'value') of every entry of a ``name: value, name: value`` string ('=' works
    too; ROS parameters have no map type), or ConfigError naming the entry."""
    out: list[tuple[str, str]] = []
    for entry in (e.strip() for e in text.strip().strip("{}").split(",")):
        if not entry:
            continue
        name, sep, value = entry.replace("=", ":").rpartition(":")
        name, value = name.strip().strip("'\""), value.strip().strip("'\"")
        if not sep or not name or not value:
            raise ConfigError(key, f"entry {entry!r} is not {form}")
        if any(name == seen for seen, _ in out):
            raise ConfigError(key, f"joint {name!r} is given twice")
        out.append((name, value))
    return out


def parse_locked_joints(text: str) -> dict[str, float]:
    """``model.locked_joints`` ('name: value, name: value') as a dict, or ConfigError naming
    the entry."""
    form = "'joint_name: value' (a finite number)"
    out: dict[str, float] = {}
    for name, value in _name_map_entries(text, "model.locked_joints", form):
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not math.isfinite(number):
            raise ConfigError("model.locked_joints", f"entry '{name}: {value}' is not {form}")
        out[name] = number
    return out


def parse_patient_joints(text: str) -> dict[str, tuple[str, float]]:
    """``patient.joints`` ('patient_joint: arm_joint, ...'; '-arm_joint': the patient's angle
    grows as the arm joint's falls) as {patient joint: (arm joint, +1 or -1)} in the order
    given, or ConfigError naming the entry (an arm joint given twice too)."""
    out = {}
    for patient, arm in _name_map_entries(text, PATIENT_JOINTS,
                                          "'patient_joint: arm_joint' or '-arm_joint'"):
        sign = -1.0 if arm.startswith("-") else 1.0
        out[patient] = (arm.lstrip("+-").strip(), sign)
    targets = [arm for arm, _ in out.values()]
    twice = next((t for t in targets if targets.count(t) > 1), None)
    if twice is not None:
        raise ConfigError(PATIENT_JOINTS, f"arm joint {twice!r} is given to two of the "
                          "patient's joints (one patient joint per arm joint)")
    return out


def patient_joint_names(values: Mapping[str, Any]) -> list[str]:
    """The joints every ``patient.*`` per-joint list is for, in its order: the patient's
    (``patient.joints``), or the arm's ``joint_names`` when it is empty."""
    return list(parse_patient_joints(values[PATIENT_JOINTS])) or list(values["joint_names"])
