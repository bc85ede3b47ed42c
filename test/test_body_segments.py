"""A person's arm segments (core/arm/body_segments.py): de Leva (1996) Table 4 scaled by body
mass and height against hand-computed values, placed in a link's frame, and added to a chain's
body exactly as the same segment written into the URDF as a fixed link."""

from __future__ import annotations

import numpy as np
import pytest

from exo_ilc_ros.core.arm.body_segments import (
    SegmentPlacement,
    Sex,
    arm_segments,
    segment_inertial,
    with_segments,
)
from exo_ilc_ros.core.arm.urdf_chain import read_urdf_chain
from exo_ilc_ros.core.params.urdf_xml import UrdfError

ARM = """<robot name="exo2">
  <link name="base"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0" rpy="0.2 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="40" velocity="3"/>
  </joint>
  <link name="upper">
    <inertial><origin xyz="0 0 -0.15" rpy="0 0 0"/><mass value="1.4"/>
      <inertia ixx="0.012" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.002"/></inertial>
  </link>
  <joint name="cuff_joint" type="fixed">
    <parent link="upper"/><child link="cuff"/><origin xyz="0.03 0 -0.1" rpy="0 0 0.5"/>
  </joint>
  <link name="cuff"/>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0 0 -0.3" rpy="0 0.4 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="20" velocity="3"/>
  </joint>
  <link name="fore">
    <inertial><origin xyz="0 0 -0.12" rpy="0 0 0"/><mass value="1.1"/>
      <inertia ixx="0.008" ixy="0" ixz="0" iyy="0.008" iyz="0" izz="0.001"/></inertial>
  </link>
</robot>
"""


def test_worked_example_male_75_kg_177_cm() -> None:
    """The note's worked example (de Leva Table 4, male, 75 kg, 1.77 m), to its printed digits."""
    upper, fore, hand = arm_segments(75.0, 1.77, Sex.MALE)
    expected = {  # m kg, L mm, CM mm, I_sag, I_trans, I_long kg m^2
        "upper_arm": (2.033, 286.4, 165.3, 0.01354, 0.01206, 0.00416),
        "forearm": (1.215, 273.4, 125.0, 0.00692, 0.00638, 0.00133),
        "hand": (0.458, 87.6, 69.2, 0.00139, 0.00092, 0.00056),
    }
    for segment in (upper, fore, hand):
        m, length, com, i_sag, i_trans, i_long = expected[segment.name]
        # within half a unit of the printed last digit (and a rounding hair: 2.0325 -> 2.033)
        assert segment.mass == pytest.approx(m, abs=5.0001e-4)
        assert 1000 * segment.length == pytest.approx(length, abs=0.050001)
        assert 1000 * segment.com_distance == pytest.approx(com, abs=0.050001)
        assert segment.inertia_sagittal == pytest.approx(i_sag, abs=5.0001e-6)
        assert segment.inertia_transverse == pytest.approx(i_trans, abs=5.0001e-6)
        assert segment.inertia_longitudinal == pytest.approx(i_long, abs=5.0001e-6)
    # upper arm, the last digits: 0.0271 x 75 and 281.7 mm x 1.77 / 1.741
    assert upper.mass == pytest.approx(2.0325, rel=1e-12)
    assert upper.length == pytest.approx(0.2863923, rel=1e-6)
    # the parallel-axis value at the shoulder, I_trans + m d^2 = 0.0676 (note)
    assert upper.inertia_transverse + upper.mass * upper.com_distance ** 2 == pytest.approx(
        0.0676, abs=5e-5)


def test_female_and_measured_lengths() -> None:
    """Female, 60 kg, 1.65 m (by hand: upper arm 0.0255 x 60 = 1.530 kg, L = 275.1 x 1.65 /
    1.735 = 261.6 mm, CM 0.5754 L = 150.5 mm, I_sag = 1.53 (0.278 x 0.2616)^2 = 0.008093);
    a measured forearm of 0.25 m replaces the scaled one."""
    upper, fore, _ = arm_segments(60.0, 1.65, "female", lengths={"forearm": 0.25})
    assert upper.mass == pytest.approx(1.530, abs=5e-4)
    assert 1000 * upper.length == pytest.approx(261.6, abs=0.05)
    assert 1000 * upper.com_distance == pytest.approx(150.5, abs=0.05)
    assert upper.inertia_sagittal == pytest.approx(0.008093, abs=5e-7)
    assert fore.length == 0.25
    assert fore.com_distance == pytest.approx(0.4559 * 0.25, rel=1e-12)
    assert fore.inertia_longitudinal == pytest.approx(0.0138 * 60 * (0.094 * 0.25) ** 2,
                                                      rel=1e-12)
    with pytest.raises(ValueError, match="unknown segment"):
        arm_segments(60.0, 1.65, lengths={"shin": 0.4})
    with pytest.raises(ValueError, match="must be > 0"):
        arm_segments(0.0, 1.65)


def test_placement_in_a_link_frame() -> None:
    """Segment along -z from (0.03, 0, -0.1), sagittal axis x: the transverse axis is -y, the
    tensor diag(I_sag, I_trans, I_long) and the centre of mass 165 mm down."""
    upper = arm_segments(75.0, 1.77)[0]
    mass, com, inertia = segment_inertial(
        upper, SegmentPlacement("cuff", (0.03, 0.0, -0.1), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0)))
    assert mass == upper.mass
    np.testing.assert_allclose(com, [0.03, 0.0, -0.1 - upper.com_distance], atol=1e-15)
    np.testing.assert_allclose(inertia, np.diag([upper.inertia_sagittal,
                                                 upper.inertia_transverse,
                                                 upper.inertia_longitudinal]), atol=1e-18)
    with pytest.raises(ValueError, match="normal to the segment"):
        segment_inertial(upper, SegmentPlacement("cuff", (0, 0, 0), (0, 0, -1), (0, 1, 1)))


def test_segments_added_as_the_urdf_would_hold_them() -> None:
    """The upper arm on the (rotated) cuff link and the forearm on the forearm link give the
    kernels the arrays of the same URDF with the segments written in as fixed links."""
    chain = read_urdf_chain(ARM, "base", "fore")
    upper, fore, hand = arm_segments(70.0, 1.75)
    placements = {
        "upper_arm": SegmentPlacement("cuff", (-0.03, 0.01, 0.1), (0.0, 0.3, -1.0),
                                      (1.0, 0.0, 0.0)),
        "forearm": SegmentPlacement("fore", (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    }
    ours = with_segments(chain, (upper, fore, hand), placements)  # the hand: no placement
    text = ARM
    for segment, placement in ((upper, placements["upper_arm"]), (fore, placements["forearm"])):
        mass, com, i = segment_inertial(segment, placement)
        com, i = com.tolist(), i.tolist()
        text = text.replace("</robot>", f"""
  <joint name="{segment.name}_joint" type="fixed">
    <parent link="{placement.link}"/><child link="{segment.name}"/>
  </joint>
  <link name="{segment.name}">
    <inertial><origin xyz="{com[0]!r} {com[1]!r} {com[2]!r}" rpy="0 0 0"/>
      <mass value="{mass!r}"/>
      <inertia ixx="{i[0][0]!r}" ixy="{i[0][1]!r}" ixz="{i[0][2]!r}" iyy="{i[1][1]!r}"
               iyz="{i[1][2]!r}" izz="{i[2][2]!r}"/></inertial>
  </link>
</robot>""")
    written = read_urdf_chain(text, "base", "fore")
    for a, b in zip(ours.kernel_args, written.kernel_args, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15)
    assert ours.masses[0] == pytest.approx(1.4 + upper.mass)
    with pytest.raises(UrdfError, match="link 'glove' is not in the chain"):
        with_segments(chain, (hand,), {"hand": SegmentPlacement("glove", (0, 0, 0), (0, 0, -1),
                                                                (1, 0, 0))})
