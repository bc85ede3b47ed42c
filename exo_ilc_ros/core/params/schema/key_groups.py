"""The digest key groups and the vocabularies of the arm's keys: which keys name a URDF arm,
a cone arm, a person (left out of a digest when unused), the joint axis names."""

from __future__ import annotations

AXIS_VECTORS: dict[str, tuple[float, float, float]] = {
    "x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0),
    "-x": (-1.0, 0.0, 0.0), "-y": (0.0, -1.0, 0.0), "-z": (0.0, 0.0, -1.0),
}
"""Joint axis names accepted in the config, as unit vectors of the link frame."""

MODEL_SOURCES = ("cones", "urdf")
URDF_JOINT_DYNAMICS = ("ignore", "apply")
"""``model.urdf_joint_dynamics``: the URDF's ``<dynamics damping friction>`` left out of the
plant, or applied as explicit joint torques (core/arm/build.py, :func:`urdf_joint_dynamics`)."""
CONE_KEYS = ("model.link_masses", "model.link_lengths", "model.radius_proximal",
             "model.radius_distal", "model.joint_axes")
"""The arm of ``model.source: cones`` (unused, and not checked per joint, for a URDF arm)."""
URDF_KEYS = ("model.source", "model.urdf", "model.base_link", "model.tip_link",
             "model.locked_joints")
"""What names a URDF arm (left out of every digest of a cone arm: its keys stay as they were)."""
URDF_PLANT_KEYS = ("model.urdf_joint_dynamics",)
"""What a URDF arm's plant adds to its rigid body (not its nominal model; left out of every
digest of a cone arm, as :data:`URDF_KEYS`)."""


PERSON_SEGMENTS = ("upper_arm", "forearm", "hand")
"""The person's segments (core/arm/body_segments.py): shoulder -> elbow, elbow -> wrist, wrist
-> third metacarpal head."""
PERSON_KEYS = ("person.enabled", "person.in_nominal", "person.body_mass", "person.height",
               "person.sex", *(f"person.{segment}.{what}" for segment in PERSON_SEGMENTS
                               for what in ("link", "length", "origin", "direction",
                                            "sagittal_axis")))
"""A person in the exoskeleton (left out of every digest while ``person.enabled`` is false:
a run without a person keeps the keys it had before they existed)."""
PATIENT_JOINTS = "patient.joints"
DRIVE_KEYS = tuple(f"person.drive.{name}" for name in (
    "mas_grade", "tone", "length_threshold", "velocity_threshold", "length_gain", "velocity_gain",
    "reflex_max", "reflex_delay", "spastic_muscles", "voluntary_gain", "fatigue_rate",
    "recovery_rate"))
"""A musculoskeletal person's neural drive (core/person/neural_drive.py): left out of every
digest while ``musculoskeletal.model`` is none (no muscles to drive), so a run keeps the
digest it had before they existed."""
STRAPPED_KEYS = ("musculoskeletal.model", "musculoskeletal.timestep",
                 "musculoskeletal.settle_time", "musculoskeletal.body_size",
                 "strapping.shoulder_joint",
                 "strapping.elbow_joint", "strapping.misalignment.offset",
                 "strapping.misalignment.rotation", "strapping.upper_arm_cuff",
                 "strapping.forearm_cuff", "strapping.stiffness", "strapping.damping",
                 "strapping.rotational_stiffness", "strapping.rotational_damping",
                 "safety.cuff_force_limit")
"""A person with muscles strapped in the exoskeleton (core/person/strapped.py, the schema's
musculoskeletal.py): left out of every digest while ``musculoskeletal.model`` is none, so a
run keeps the digest it had before they existed."""
BODY_SIZE_KEYS = ("person.body_mass", "person.height", "person.sex")
"""The person's body size: de Leva's segments of the URDF person (``person.enabled``) and the
size a person with muscles is scaled to (``musculoskeletal.body_size: person``)."""
