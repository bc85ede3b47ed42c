"""The arm as the live view shows it and every bag records it (:data:`topics.VIEW_TYPES`):
``/robot_description`` (the URDF of the run's arm, ``std_msgs/String``, as
robot_state_publisher publishes it), ``/reference/robot_description`` (the same arm with every
link prefixed :data:`REFERENCE_PREFIX`) and, per JointState sample, ``/tf``
(``tf2_msgs/TFMessage`` stamped with the sample's stamp): one parent -> child transform per
joint of the measured arm (:class:`~exo_ilc_ros.core.arm.forward_kinematics.UrdfKinematics`),
the reference arm's base :data:`REFERENCE_OFFSET` beside it, and the reference pose q_d(t_i)
of the last feed-forward's trial at that sample on the ``reference/`` tree.

With a person strapped in, the person too (``core/person/display.py``): from its display URDF
(``/person/robot_description``, which the plant publishes, :meth:`ArmView.load_person`) and
each ``/person/joint_states`` sample a ``/tf`` of the person's frames ``person/<body>`` on the
arm's root link, stamped with the sample (:meth:`ArmView.person_tf`): the person where MuJoCo
has it, not rigidly on the exoskeleton's links.

One :class:`ArmView` serves the live view (``nodes/foxglove_bridge.py``), the graph's recorder
(``nodes/bag_recorder.py``, between trials) and ``exo-ilc simulate --bag``
(:mod:`.run_writer`), so all three carry the same messages for the same samples.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from ..core.arm.build import view_urdf
from ..core.arm.forward_kinematics import UrdfKinematics
from ..core.params.config import Config
from ..wire import topics
from ..wire.cdr import read_joint_state, read_trajectory_positions
from ..wire.tf import tf_message
from .messages import serialize, typestore

REFERENCE_PREFIX = "reference/"
REFERENCE_OFFSET = (0.0, 0.6, 0.0)
"""m: where the reference arm's base stands in the measured arm's root link frame
(``base_link`` for the paper's arm)."""


def prefixed_urdf(urdf: str, prefix: str) -> str:
    """The URDF with every link (and joint) name prefixed: a second arm on its own TF tree."""
    root = ET.fromstring(urdf)
    root.set("name", prefix + str(root.get("name", "")))
    for element in root.iter():
        if element.tag in ("link", "joint") and element.get("name"):
            element.set("name", prefix + str(element.get("name")))
        if element.tag in ("parent", "child") and element.get("link"):
            element.set("link", prefix + str(element.get("link")))
    return ET.tostring(root, encoding="unicode")


def string_message(text: str) -> bytes:
    """``std_msgs/msg/String`` CDR."""
    return serialize(typestore().types["std_msgs/msg/String"](data=text), "std_msgs/msg/String")


class ArmView:
    """The view's messages for one run's arm (``config``): the URDFs, and /tf per sample."""

    def __init__(self, config: Config) -> None:
        self.joint_names: list[str] = list(config["joint_names"])
        self.period_ns = int(round(float(config["control.period"]) * 1e9))
        self.urdf, self.fixed_positions, self.root_link = view_urdf(config)
        """The arm's URDF (a URDF arm's own), its locked joints' values and its root link."""
        self.reference_urdf = prefixed_urdf(self.urdf, REFERENCE_PREFIX)
        self.kinematics = UrdfKinematics(self.urdf)
        self.reference_kinematics = UrdfKinematics(self.reference_urdf)
        self.reference_names = [REFERENCE_PREFIX + n for n in self.joint_names]
        self.reference: tuple[int, np.ndarray] | None = None
        """(t0 ns, q_d per sample) of the last feed-forward loaded."""
        self.person: UrdfKinematics | None = None
        """A person strapped in: the kinematics of its display URDF (:meth:`load_person`)."""

    def descriptions(self) -> dict[str, bytes]:
        """``/robot_description`` and ``/reference/robot_description`` (CDR)."""
        return {topics.ROBOT_DESCRIPTION: string_message(self.urdf),
                topics.REFERENCE_DESCRIPTION: string_message(self.reference_urdf)}

    def load_person(self, raw: bytes) -> None:
        """The person's display URDF (a ``/person/robot_description`` message, CDR:
        ``core/person/display.py``), for :meth:`person_tf`. ValueError (nothing changed) for
        one that is not a URDF."""
        try:
            text = str(typestore().deserialize_cdr(raw, "std_msgs/msg/String").data)
            self.person = UrdfKinematics(text)
        except Exception as exc:  # a foreign or damaged message
            raise ValueError(f"not a person's URDF: {exc}") from None

    def person_tf(self, raw: bytes) -> tuple[int, bytes] | None:
        """(stamp, /tf CDR) of one ``/person/joint_states`` message (CDR): every joint of the
        person's URDF (its placement on the arm's root link, each body's joints at the
        sample's angles, the fixed ones), stamped with the sample's stamp; None before the
        URDF (:meth:`load_person`) or for a sample that is not the person's."""
        if self.person is None:
            return None
        try:
            stamp, position, _ = read_joint_state(raw)
        except ValueError:
            return None
        if position.shape[0] != len(self.person.moving):
            return None
        transforms = self.person.transforms(dict(zip(self.person.moving, position.tolist(),
                                                     strict=True)))
        return stamp, tf_message(stamp, transforms)

    def sample_tf(self, topic: str, raw: bytes) -> tuple[int, bytes] | None:
        """The /tf of one per-sample message of ``topic``: the arm's (:meth:`tf`) or the
        person's (:meth:`person_tf`); None for another topic."""
        if topic == topics.JOINT_STATES:
            return self.tf(raw)
        if topic == topics.PERSON_JOINT_STATES:
            return self.person_tf(raw)
        return None

    def load_reference(self, raw: bytes) -> None:
        """The reference of the trial a /ilc/feedforward message (CDR) profiles: its t0 (the
        header stamp) and q_d per sample. ValueError (the reference unchanged) for a profile
        that does not name this arm's joints."""
        try:
            stamp, names, positions = read_trajectory_positions(raw)
            order = [names.index(n) for n in self.joint_names]
            q = positions[:, order]
        except Exception as exc:  # a foreign or damaged profile
            raise ValueError(f"feed-forward without this arm's reference: {exc}") from None
        self.reference = (stamp, q)

    def tf(self, raw: bytes) -> tuple[int, bytes] | None:
        """(stamp, /tf CDR) of one /joint_states message (CDR): the arm's joints at the
        sample's position and, on the ``reference/`` tree, q_d at the same sample of the loaded
        reference's trial (by the stamp: t0 + i period); None for a sample that is not this
        arm's."""
        try:
            stamp, position, _ = read_joint_state(raw)
        except ValueError:
            return None
        if position.shape[0] != len(self.joint_names):
            return None
        transforms = self.kinematics.transforms(
            {**self.fixed_positions, **dict(zip(self.joint_names, position.tolist(),
                                                strict=True))})
        transforms.append((self.root_link, REFERENCE_PREFIX + self.root_link, REFERENCE_OFFSET,
                           (0.0, 0.0, 0.0, 1.0)))
        if self.reference is not None:
            t0, q_d = self.reference
            i = int(round((stamp - t0) / self.period_ns))
            if 0 <= i < q_d.shape[0]:
                transforms += self.reference_kinematics.transforms(
                    {**{REFERENCE_PREFIX + k: v for k, v in self.fixed_positions.items()},
                     **dict(zip(self.reference_names, q_d[i].tolist(), strict=True))})
        return stamp, tf_message(stamp, transforms)
