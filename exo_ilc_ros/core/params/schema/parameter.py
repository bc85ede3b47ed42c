"""A parameter of the schema (:class:`Parameter`, :class:`Kind`) and its ROS sections."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

SHARED = "/**"
PLANT = "plant_simulator"
CONTROLLER = "computed_torque_controller"
SUPERVISOR = "ilc_supervisor"
SECTIONS = (SHARED, PLANT, CONTROLLER, SUPERVISOR)
ROS_BUILTIN = frozenset({"use_sim_time", "start_type_description_service"})
"""Parameters every rclpy node owns; accepted in any section, not part of the schema."""


class Kind(Enum):
    """ROS parameter types used by the schema."""

    DOUBLE = "double"
    INTEGER = "integer"
    BOOL = "bool"
    STRING = "string"
    DOUBLE_ARRAY = "double_array"
    STRING_ARRAY = "string_array"


@dataclass(frozen=True)
class Parameter:
    """One parameter: name, section, type, meaning and the rule its value must follow."""

    name: str
    section: str
    kind: Kind
    description: str
    per_joint: bool = False
    """An array with one entry per joint, or one value for every joint, or a map by joint name
    (:func:`.validator.per_joint_values`: the one rule for every per-joint key)."""
    patient_joint: bool = False
    """Per joint of the patient (:func:`patient_joint_names`), not of the arm."""
    minimum: float | None = None
    strictly_positive: bool = False
    choices: tuple[str, ...] = ()
    live: bool = False
    """May change while the graph runs (takes effect at the next trial boundary)."""
    extra_rule: Callable[[Any], str | None] | None = field(default=None, compare=False)
