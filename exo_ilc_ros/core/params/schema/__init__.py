"""The parameter schema: every parameter's name, ROS section, type and rule, one registry.

Names are the dotted ROS parameter names (nested YAML keys joined by '.'). ``section`` says where
the parameter lives in the ROS parameter YAML: ``/**`` (read by every node) or one node's name.
Values come from the YAML in ``config/``; this package holds no defaults, only the rules. One
module per section: the parameter table (:mod:`.table`, where new keys go), the parameter type
(:mod:`.parameter`), the rule functions (:mod:`.rules`), the string-map parsers
(:mod:`.string_maps`), the digest key groups (:mod:`.key_groups`) and the validator
(:mod:`.validator`). Read it through this package (``schema.PARAMETERS``, ``schema.BY_NAME``):
YAML loading, ROS declaration, validation and the bags' provenance all do.
"""

from __future__ import annotations

from .key_groups import (
    AXIS_VECTORS,
    BODY_SIZE_KEYS,
    CONE_KEYS,
    DRIVE_KEYS,
    MODEL_SOURCES,
    PATIENT_JOINTS,
    PERSON_KEYS,
    PERSON_SEGMENTS,
    STRAPPED_KEYS,
    URDF_JOINT_DYNAMICS,
    URDF_KEYS,
    URDF_PLANT_KEYS,
)
from .parameter import (
    CONTROLLER,
    PLANT,
    ROS_BUILTIN,
    SECTIONS,
    SHARED,
    SUPERVISOR,
    Kind,
    Parameter,
)
from .rules import (
    MAS_GRADES,
)
from .string_maps import (
    parse_locked_joints,
    parse_patient_joints,
    patient_joint_names,
)
from .table import (
    BY_NAME,
    PARAMETERS,
    parameters_of,
)
from .validator import (
    OTHER_JOINTS,
    check_consistency,
    check_patient_joints,
    check_value,
    coerce,
    per_joint_values,
    period_problem,
)

__all__ = [
    "AXIS_VECTORS",
    "BODY_SIZE_KEYS",
    "BY_NAME",
    "CONE_KEYS",
    "CONTROLLER",
    "DRIVE_KEYS",
    "MAS_GRADES",
    "MODEL_SOURCES",
    "OTHER_JOINTS",
    "PARAMETERS",
    "PATIENT_JOINTS",
    "PERSON_KEYS",
    "PERSON_SEGMENTS",
    "PLANT",
    "ROS_BUILTIN",
    "SECTIONS",
    "SHARED",
    "STRAPPED_KEYS",
    "SUPERVISOR",
    "URDF_JOINT_DYNAMICS",
    "URDF_KEYS",
    "URDF_PLANT_KEYS",
    "Kind",
    "Parameter",
    "check_consistency",
    "check_patient_joints",
    "check_value",
    "coerce",
    "parameters_of",
    "parse_locked_joints",
    "parse_patient_joints",
    "patient_joint_names",
    "per_joint_values",
    "period_problem",
]
