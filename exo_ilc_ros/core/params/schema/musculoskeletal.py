"""The keys of a person with muscles strapped in the exoskeleton (core/person/): the person
model, the cuffs and the misalignment, and the cuff-force limit of the safety envelope."""

from __future__ import annotations

from typing import Any

from .parameter import PLANT, SHARED, Kind, Parameter
from .rules import _vector_rule

PERSON_MODEL_CHOICES = ("none", "myoarm", "myoelbow")
SCHIEBL_2025 = ("Schiebl et al., Sensors 25(15):4605 (2025), upper-arm interface, linear "
                "subject-group fits, mean of both directions")


def _cuff_pair_rule(value: Any) -> str | None:
    if len(value) != 2 or any(v < 0.0 for v in value):
        return f"must be [upper_arm, forearm] (2 numbers >= 0; 0: no limit), got {value!r}"
    return None


def _positive_vector_rule(value: Any) -> str | None:
    problem = _vector_rule(value)
    if problem is None and any(v < 0.0 for v in value):
        return f"must be >= 0 on every axis, got {value!r}"
    return problem


def musculoskeletal_parameters() -> list[Parameter]:
    """musculoskeletal.*, strapping.* and the cuff limits of safety.*."""

    def p(name: str, kind: Kind, text: str, **rules: Any) -> Parameter:
        return Parameter(name, PLANT, kind, text, **rules)

    axes = "per cuff axis [x mediolateral (the elbow axis), y anteroposterior, z along the limb]"
    return [
        p("musculoskeletal.model", Kind.STRING, "a person with muscles strapped in the "
          "exoskeleton (core/person/, docs/person-with-muscles.md): none (the plant is the "
          "arm alone), myoarm (MyoSuite's MyoArm, right arm, hand pruned) or myoelbow "
          "(MyoSuite's 2-DOF, 6-muscle elbow model)", choices=PERSON_MODEL_CHOICES),
        p("musculoskeletal.timestep", Kind.DOUBLE, "MuJoCo's step of the strapped model "
          "(s; implicitfast; must divide control.period)", strictly_positive=True),
        p("musculoskeletal.settle_time", Kind.DOUBLE, "simulated s the person hangs in the "
          "cuffs, the exoskeleton held at x_d(0), before the state every trial starts from "
          "is kept", minimum=0.0),
        p("musculoskeletal.body_size", Kind.STRING, "model: the person model's own adult as "
          "MyoSuite builds it; person: its upper arm and forearm scaled to person.height, "
          "person.body_mass and person.sex by de Leva's (1996) segments, the muscles' lengths "
          "and peak forces with them (core/person/body_size.py)",
          choices=("model", "person")),
        p("strapping.shoulder_joint", Kind.STRING, "the exoskeleton joint placed on the "
          "person's shoulder centre (its body takes the upper-arm cuff); empty: the first of "
          "joint_names"),
        p("strapping.elbow_joint", Kind.STRING, "the exoskeleton joint placed on the person's "
          "elbow flexion axis (its body takes the forearm cuff); empty: the last of "
          "joint_names"),
        p("strapping.misalignment.offset", Kind.DOUBLE_ARRAY, "the exoskeleton moved from the "
          "fit to the person's joints, mm along its base axes (x the elbow axis, z up the "
          "upper arm)", extra_rule=_vector_rule),
        p("strapping.misalignment.rotation", Kind.DOUBLE_ARRAY, "the exoskeleton turned about "
          "the person's shoulder centre, deg about its base axes x, y, z in turn",
          extra_rule=_vector_rule),
        p("strapping.upper_arm_cuff", Kind.DOUBLE, "m from the shoulder centre along the "
          "humerus to the upper-arm cuff", strictly_positive=True),
        p("strapping.forearm_cuff", Kind.DOUBLE, "m from the elbow centre towards the "
          "forearm's centre of mass to the forearm cuff", strictly_positive=True),
        p("strapping.stiffness", Kind.DOUBLE_ARRAY, f"each cuff's translational stiffness "
          f"(N/m), {axes}; default from {SCHIEBL_2025} (3.15, 3.7, 2.25 N/mm)",
          extra_rule=_positive_vector_rule),
        p("strapping.damping", Kind.DOUBLE_ARRAY, f"each cuff's translational damping "
          f"(N s/m), {axes}; NOT measured: no published arm-cuff damping was found, the "
          "default is chosen (~0.3 of critical for a 1 kg segment)",
          extra_rule=_positive_vector_rule),
        p("strapping.rotational_stiffness", Kind.DOUBLE_ARRAY, f"each cuff's rotational "
          f"stiffness (N m/rad), {axes}; default from {SCHIEBL_2025} (0.21, 0.185, 0.035 "
          "N m/deg)", extra_rule=_positive_vector_rule),
        p("strapping.rotational_damping", Kind.DOUBLE_ARRAY, f"each cuff's rotational damping "
          f"(N m s/rad), {axes}; NOT measured (chosen, as strapping.damping)",
          extra_rule=_positive_vector_rule),
        Parameter("safety.cuff_force_limit", SHARED, Kind.DOUBLE_ARRAY,
                  "|force| a cuff may press into the person, [upper_arm, forearm] (N; 0: no "
                  "limit): the first sample past it aborts the trial (safe hold, as the "
                  "error envelope). Default: ISO/TS 15066:2016 Table A.2, the permissible "
                  "quasi-static contact force on the upper arm (150 N) and the lower arm "
                  "(160 N)", extra_rule=_cuff_pair_rule),
    ]
