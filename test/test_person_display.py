"""The person as the view draws it (``core/person/display.py``): the display URDF's forward
kinematics (the view's own, ``UrdfKinematics``) at the person's joint angles puts every body of
the person where MuJoCo's ``mj_kinematics`` has it, hung from the exoskeleton's root link
where the strapped model places the exoskeleton (its joints' anchors checked too, through the
arm's URDF); the URDF is well-formed and draws segments; and simulate's bag of a person holds
the URDF once and per sample the person's joints and their /tf."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core.arm.build import view_urdf
from exo_ilc_ros.core.arm.forward_kinematics import UrdfKinematics
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.person.display import PERSON_PREFIX, PERSON_WORLD
from exo_ilc_ros.wire import topics

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

ELBOW = config_dir() / "myoelbow.yaml"
SHORT = {"trajectory.duration": 0.3, "musculoskeletal.settle_time": 0.1, "max_trials": 2}


def _matrix(rotation: tuple[float, ...]) -> np.ndarray:
    x, y, z, w = rotation
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _pose_in(transforms: list[Any], frame: str) -> tuple[np.ndarray, str]:
    """The 4x4 pose of ``frame`` in the root its chain of transforms ends at, and that root."""
    parent_of = {child: (parent, t, r) for parent, child, t, r in transforms}
    pose = np.eye(4)
    while frame in parent_of:
        parent, translation, rotation = parent_of[frame]
        step = np.eye(4)
        step[:3, :3] = _matrix(rotation)
        step[:3, 3] = translation
        pose = step @ pose
        frame = parent
    return pose, frame


@pytest.fixture(scope="module")
def strapped() -> Any:
    from exo_ilc_ros.core.person.strapped import StrappedArm
    from exo_ilc_ros.core.sim.experiment import Experiment

    config = load_config(ELBOW, overrides=SHORT)
    return config, StrappedArm(config, Experiment(config).reference.position[0])


def test_the_urdfs_kinematics_put_every_body_where_mujoco_has_it(strapped: Any) -> None:
    """At 20 random states of the strapped model: each person body's pose from the display
    URDF (root link = the arm's) carried by the exoskeleton's base placement equals MuJoCo's
    xpos / xmat to 1e-9; each exoskeleton joint's frame from the arm's own URDF at the
    exoskeleton's q, carried the same way, sits on MuJoCo's joint anchor (so the two URDFs
    share their root frame). The URDF's moving joints are the person's, in qpos order."""
    import mujoco

    config, arm = strapped
    arm_urdf, fixed, root = view_urdf(config)
    person = UrdfKinematics(arm.person_description(root))
    exo = UrdfKinematics(arm_urdf)
    names = arm.person_joint_names()
    assert person.moving == names == ["r_shoulder_elev", "r_elbow_flex"]
    model, data = arm.model, arm.data
    base = np.eye(4)
    base[:3, :3] = arm.base_rotation
    base[:3, 3] = arm.base_position
    child_of = {j.name: j.child for j in exo.joints}
    rng = np.random.default_rng(3)
    saved = (np.array(data.qpos), np.array(data.qvel))
    checked = 0
    try:
        for _ in range(20):
            data.qpos[:] = model.qpos0 + rng.uniform(-1.0, 1.0, model.nq)
            mujoco.mj_kinematics(model, data)
            transforms = person.transforms(dict(zip(names, data.qpos[:len(names)],
                                                    strict=True)))
            for body in range(1, model.nbody):
                name = str(model.body(body).name)
                if name.startswith("exo_"):
                    continue
                pose, top = _pose_in(transforms, PERSON_PREFIX + name)
                assert top == root
                world = base @ pose
                np.testing.assert_allclose(world[:3, 3], data.xpos[body], atol=1e-9)
                np.testing.assert_allclose(world[:3, :3], data.xmat[body].reshape(3, 3),
                                           atol=1e-9)
                checked += 1
            q = dict(zip(arm.joint_names, data.qpos[len(names):], strict=True))
            arm_transforms = exo.transforms({**fixed, **q})
            for joint in arm.joint_names:
                pose, top = _pose_in(arm_transforms, child_of[joint])
                assert top == root
                np.testing.assert_allclose((base @ pose)[:3, 3],
                                           data.xanchor[model.joint("exo_" + joint).id],
                                           atol=1e-9)
    finally:
        data.qpos[:], data.qvel[:] = saved
        arm.reset()
    assert checked == 20 * 4  # full_body, base, the humerus, the forearm


def test_the_urdf_is_well_formed_and_draws_the_segments(strapped: Any) -> None:
    """The URDF parses (xml.etree), every link is ``person/`` prefixed but the arm's root;
    the humerus is drawn as one segment to the elbow (a cylinder as long as the child's
    offset, two spheres), the forearm (no child) to twice its centre of mass."""
    _, arm = strapped
    model = arm.model
    root = ET.fromstring(arm.person_description("base_link"))
    links = {link.get("name"): link for link in root.iter("link")}
    assert set(links) - {"base_link"} == {n for n in links if n and n.startswith(PERSON_PREFIX)}
    assert PERSON_WORLD in links
    humerus = links[PERSON_PREFIX + "r_humerus"]
    (cylinder,) = [g for g in humerus.iter("cylinder")]
    elbow = model.body("r_ulna_radius_hand").id
    assert float(cylinder.get("length") or 0) == pytest.approx(
        np.linalg.norm(model.body_pos[elbow]), abs=1e-12)
    assert len(list(humerus.iter("sphere"))) == 2
    (forearm,) = [g for g in links[PERSON_PREFIX + "r_ulna_radius_hand"].iter("cylinder")]
    assert float(forearm.get("length") or 0) == pytest.approx(
        2 * np.linalg.norm(model.body_ipos[elbow]), abs=1e-12)


def test_simulates_bag_holds_the_persons_urdf_joints_and_tf(tmp_path: Path) -> None:
    """simulate's bag of the elbow model: /person/robot_description once at log time 0, the
    run's URDF; per sample a /person/joint_states (the trial record's person angles, NaN
    effort) at its stamp and a /tf of the person's frames equal to the URDF's kinematics of
    them; the arm's /tf unchanged beside them (one per /joint_states)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from exo_ilc_ros.bag import write_run
    from exo_ilc_ros.core.session.learning_session import run_trials

    config = load_config(ELBOW, overrides=SHORT)
    result = run_trials(config)
    assert result.person_description
    bag = write_run(tmp_path / "bag", config, result)
    recorded: dict[str, list[tuple[int, Any]]] = {}
    for file in sorted(bag.glob("*.mcap")):
        with open(file, "rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            for _, channel, message, decoded in reader.iter_decoded_messages():
                recorded.setdefault(channel.topic, []).append((message.log_time, decoded))
    ((log, description),) = recorded[topics.PERSON_DESCRIPTION]
    assert log == 0 and description.data == result.person_description
    kinematics = UrdfKinematics(description.data)
    states = recorded[topics.PERSON_JOINT_STATES]
    samples = [(r, i) for r in result.records for i in range(r.position.shape[0])]
    assert len(states) == len(samples)
    person_tf = {}
    arm_tf = 0
    for _, msg in recorded[topics.TF]:
        frames = {t.child_frame_id for t in msg.transforms}
        stamp = msg.transforms[0].header.stamp
        if PERSON_WORLD in frames:
            person_tf[stamp.sec * 10**9 + stamp.nanosec] = msg
        else:
            arm_tf += 1
    assert arm_tf == len(recorded[topics.JOINT_STATES]) == len(samples)
    for (log, msg), (record, i) in zip(states, samples, strict=True):
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        assert log == stamp
        assert list(msg.name) == kinematics.moving
        assert list(msg.position) == list(record.person_position[i])
        assert list(msg.velocity) == list(record.person_velocity[i])
        assert np.isnan(msg.effort).all()
        expected = kinematics.transforms(dict(zip(msg.name, msg.position, strict=True)))
        got = [(t.header.frame_id, t.child_frame_id,
                (t.transform.translation.x, t.transform.translation.y,
                 t.transform.translation.z),
                (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
                 t.transform.rotation.w)) for t in person_tf[stamp].transforms]
        assert got == [(p, c, tuple(t), tuple(r)) for p, c, t, r in expected]
