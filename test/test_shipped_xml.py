"""Every XML file the package ships is well-formed XML (strict ``xml.etree`` parse).

Pinocchio and urdfdom accept a URDF whose comment holds ``--``; Python's expat and Chromium's
DOMParser (the Foxglove 3D panel's URDF loader) reject it, so only a strict parse catches it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.arm.urdf import arm_urdf
from exo_ilc_ros.core.params.config import load_config

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted([*ROOT.glob("urdf/*.urdf"), *ROOT.glob("config/layouts/*.xml"),
                  *ROOT.glob("launch/*.xml"), ROOT / "package.xml"])


def test_there_is_shipped_xml_to_check() -> None:
    names = {p.name for p in SHIPPED}
    assert "exo_arm.urdf" in names and "plotjuggler.xml" in names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: str(p.relative_to(ROOT)))
def test_shipped_xml_is_well_formed(path: Path) -> None:
    ET.parse(path)  # raises ParseError on "--" in a comment, a bad entity, ...


def test_the_generated_urdf_is_well_formed_and_the_shipped_one_is_current() -> None:
    config = load_config()
    text = arm_urdf(build_arm(config), config["joint_names"], config["control.effort_limit"])
    root = ET.fromstring(text)
    assert [j.get("name") for j in root.iter("joint")] == list(config["joint_names"])
    assert (ROOT / "urdf" / "exo_arm.urdf").read_text() == text
