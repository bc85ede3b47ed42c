"""The live view (foxglove_bridge over the Foxglove WebSocket protocol) and the bags it must
agree with: forward kinematics against Pinocchio, the /tf and trial-metrics encodings against
rosbags' decoders, and one short graph with ``--live`` read by a real WebSocket client
(subprotocol ``foxglove.sdk.v1``) that decodes every channel from its advertised schema only and
finds the run's bag in it."""

from __future__ import annotations

import glob
import json
import math
import os
import socket
import struct
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
import yaml
from live_client import SUBPROTOCOL, Received, collect
from live_clients import LiveClients
from mcap.reader import make_reader
from mcap_ros2._dynamic import generate_dynamic
from mcap_ros2.decoder import DecoderFactory

from exo_ilc_ros.bag.messages import typestore
from exo_ilc_ros.bag.view import REFERENCE_OFFSET, REFERENCE_PREFIX, prefixed_urdf
from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.arm.forward_kinematics import UrdfKinematics, quaternion
from exo_ilc_ros.core.arm.urdf import arm_urdf
from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.core.person.display import PERSON_WORLD
from exo_ilc_ros.orchestration.live import LiveView
from exo_ilc_ros.wire import topics
from exo_ilc_ros.wire.tf import TF, TF_TYPE, tf_message
from exo_ilc_ros.wire.topics import REFERENCE_DESCRIPTION, ROBOT_DESCRIPTION
from exo_ilc_ros.wire.trial_metrics import ROW_NAMES, decode, index, trial_metrics

ROOT = Path(__file__).resolve().parents[1]


def _urdf() -> str:
    config = load_config()
    return arm_urdf(build_arm(config), config["joint_names"], config["control.effort_limit"])


def _rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of (x, y, z, w), via Pinocchio (an independent conversion)."""
    x, y, z, w = q
    return np.asarray(pin.Quaternion(w, x, y, z).toRotationMatrix())


def _pinocchio_joint_placements(model: Any, data: Any, q: np.ndarray) -> dict[str, Any]:
    """Per joint name: Pinocchio's placement of the joint frame in its parent joint's."""
    pin.forwardKinematics(model, data, q)
    return {model.names[j]: data.liMi[j] for j in range(1, model.njoints)}


def _check_transforms(transforms: list[tuple[str, str, np.ndarray, np.ndarray]],
                      urdf: str, q: np.ndarray, prefix: str = "") -> int:
    """Each parent -> child transform equals Pinocchio's placement of that joint to 1e-9;
    returns how many were compared."""
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    placements = _pinocchio_joint_placements(model, data, q)
    child_of = {j.child: j.name for j in UrdfKinematics(urdf).joints}
    compared = 0
    for parent, child, translation, rotation in transforms:
        if child not in child_of:
            continue
        expected = placements[child_of[child]]
        np.testing.assert_allclose(translation, expected.translation, rtol=0, atol=1e-9,
                                   err_msg=f"{prefix}{parent}->{child}")
        np.testing.assert_allclose(_rotation(np.asarray(rotation)), expected.rotation,
                                   rtol=0, atol=1e-9, err_msg=f"{prefix}{parent}->{child}")
        compared += 1
    return compared


def test_forward_kinematics_equals_pinocchio() -> None:
    """Our URDF forward kinematics, per joint and composed to the tip, equals Pinocchio's over
    random poses to 1e-9."""
    urdf = _urdf()
    kinematics = UrdfKinematics(urdf)
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, model.nq)
        transforms = kinematics.transforms(dict(zip(kinematics.moving, q, strict=True)))
        assert _check_transforms(transforms, urdf, q) == model.nq
        pin.forwardKinematics(model, data, q)
        pose = np.eye(4)
        for _, _, translation, rotation in transforms:
            step = np.eye(4)
            step[:3, :3], step[:3, 3] = _rotation(rotation), translation
            pose = pose @ step
        np.testing.assert_allclose(pose[:3, 3], data.oMi[model.njoints - 1].translation,
                                   atol=1e-9)
        np.testing.assert_allclose(pose[:3, :3], data.oMi[model.njoints - 1].rotation,
                                   atol=1e-9)


def test_quaternion_of_every_kind_of_rotation() -> None:
    """The quaternion branch for each largest diagonal, against Pinocchio's conversion."""
    for axis in (np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]),
                 np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])):
        for angle in (0.0, 0.3, 2.9, math.pi, -3.0):
            rotation = np.asarray(pin.AngleAxis(angle, axis).toRotationMatrix())
            np.testing.assert_allclose(_rotation(quaternion(rotation)), rotation, atol=1e-12)


def test_tf_message_decodes_with_rosbags() -> None:
    transforms = [("base_link", "shoulder_link", np.array([0.0, 0.1, -0.2]),
                   np.array([0.0, 0.0, 0.0, 1.0])),
                  ("reference/a", "reference/bb", np.array([1.5, -2.0, 3.25]),
                   np.array([0.5, 0.5, 0.5, 0.5]))]
    msg = typestore().deserialize_cdr(tf_message(12_345_678_901, transforms), TF_TYPE)
    assert len(msg.transforms) == 2
    for got, (parent, child, translation, rotation) in zip(msg.transforms, transforms,
                                                           strict=True):
        assert (got.header.stamp.sec, got.header.stamp.nanosec) == (12, 345_678_901)
        assert (got.header.frame_id, got.child_frame_id) == (parent, child)
        t, r = got.transform.translation, got.transform.rotation
        assert [t.x, t.y, t.z] == list(translation) and [r.x, r.y, r.z, r.w] == list(rotation)


def test_trial_metrics_from_a_summary_and_back() -> None:
    names = ["a", "b"]
    values = {"trial": "3", "max_abs_error/a": "0.5", "max_abs_error/b": "0.25",
              "metric/rms_error/a": "0.1", "metric/rms_error/b": "0.2",
              "level/M/a": "0.01", "level/M/b": "nan"}
    array = trial_metrics(values, names, warn=True)
    assert array.data[:2] == [3.0, 1.0] and array.data_offset == 2
    assert array.data[index("max_abs_error", 1, 2)] == 0.25
    assert array.data[index("level/M", 0, 2)] == 0.01
    assert math.isnan(array.data[index("level/M", 1, 2)])
    assert math.isnan(array.data[index("max_abs_feedforward", 0, 2)])  # absent: nan
    assert len(array.data) == 2 + len(ROW_NAMES) * 2
    back = decode([d.label for d in array.dims], array.data_offset, array.data)
    assert back["trial"] == 3 and back["level"] == 1
    assert back["rms_error"] == {"a": 0.1, "b": 0.2}


def test_the_reference_urdf_is_well_formed_and_prefixed() -> None:
    root = ET.fromstring(prefixed_urdf(_urdf(), REFERENCE_PREFIX))
    links = [link.get("name") for link in root.iter("link")]
    assert links and all(str(n).startswith(REFERENCE_PREFIX) for n in links)
    assert {j.find("parent").get("link") for j in root.iter("joint")} <= set(links)  # type: ignore[union-attr]


def test_the_shipped_layout_draws_the_views_channels() -> None:
    """config/layouts/foxglove.json: the per-trial plots index /ilc/trial_metrics where the
    layout puts each joint's value, x = the trial; the error plot draws its user script's
    output; the 3D panel shows the URDF and the reference arm on the ``reference/`` frames."""
    import json

    layout = json.loads((ROOT / "config" / "layouts" / "foxglove.json").read_text())
    panels = layout["configById"]
    names = list(load_config()["joint_names"])
    for panel, row in (("Plot!max_error", "max_abs_error"), ("Plot!rms_error", "rms_error"),
                       ("Plot!level_M", "level/M")):
        config = panels[panel]
        assert config["xAxisPath"]["value"] == f"{topics.TRIAL_METRICS}.data[0]"
        assert [p["value"] for p in config["paths"]] == \
            [f"{topics.TRIAL_METRICS}.data[{index(row, j, len(names))}]"
             for j in range(len(names))]
        assert [p["label"] for p in config["paths"]] == names
    (script,) = layout["userNodes"].values()
    assert 'export const output = "/studio_script/tracking_error"' in script["sourceCode"]
    assert all(p["value"].startswith("/studio_script/tracking_error.error[")
               for p in panels["Plot!tracking_error"]["paths"])
    three_d = panels["3D!arm"]
    assert three_d["topics"][ROBOT_DESCRIPTION]["visible"] and three_d["followTf"] == "base_link"
    reference = three_d["layers"]["reference"]
    assert (reference["topic"], reference["framePrefix"]) == (ROBOT_DESCRIPTION, REFERENCE_PREFIX)
    assert panels["DiagnosticSummary!diagnostics"]["topicToRender"] == topics.DIAGNOSTICS
    assert "Plot!identified_damping" not in panels  # the shipped config identifies nothing


def _transform_values(msg: Any) -> tuple[Any, ...]:
    """A decoded TFMessage as plain values (for equality between decoders)."""
    return tuple((_stamp(t), t.header.frame_id, t.child_frame_id,
                  t.transform.translation.x, t.transform.translation.y,
                  t.transform.translation.z, t.transform.rotation.x, t.transform.rotation.y,
                  t.transform.rotation.z, t.transform.rotation.w) for t in msg.transforms)


def _assert_tf_is_forward_kinematics(tf: list[tuple[int, Any]], states: dict[int, Any],
                                     profiles: dict[int, Any]) -> None:
    """``tf`` ((log time, decoded TFMessage)) holds one message per sample of ``states`` (by
    stamp), logged and stamped at the sample's stamp: the arm's transforms = Pinocchio's
    forward kinematics of the sample's q, the reference arm's base at its offset and its
    transforms = Pinocchio's of q_d at that sample of the latest feed-forward (``profiles``
    by t0), each to 1e-9."""
    config = load_config()
    names = list(config["joint_names"])
    urdf = _urdf()
    reference_urdf = prefixed_urdf(urdf, REFERENCE_PREFIX)
    period = int(config["control.period"] * 1e9)
    stamps = []
    reference_checked = 0
    for log, msg in tf:
        stamp = _stamp(msg.transforms[0])
        assert log == stamp and all(_stamp(t) == stamp for t in msg.transforms)
        stamps.append(stamp)
        transforms = [(t.header.frame_id, t.child_frame_id,
                       np.array([t.transform.translation.x, t.transform.translation.y,
                                 t.transform.translation.z]),
                       np.array([t.transform.rotation.x, t.transform.rotation.y,
                                 t.transform.rotation.z, t.transform.rotation.w]))
                      for t in msg.transforms]
        sample = states[stamp]
        q = np.array([sample.position[list(sample.name).index(n)] for n in names])
        assert _check_transforms(transforms, urdf, q) == len(names)
        base = [t for t in transforms if t[1] == REFERENCE_PREFIX + "base_link"]
        assert len(base) == 1 and list(base[0][2]) == list(REFERENCE_OFFSET)
        t0 = max((t for t in profiles if t <= stamp), default=None)
        if t0 is not None and (stamp - t0) // period < len(profiles[t0].points):
            point = profiles[t0].points[(stamp - t0) // period]
            q_d = np.array([point.positions[list(profiles[t0].joint_names).index(n)]
                            for n in names])
            reference_checked += _check_transforms(transforms, reference_urdf, q_d,
                                                   "reference ")
    assert sorted(stamps) == sorted(states)
    assert reference_checked == len(names) * len(states)


def _assert_descriptions(recorded: dict[str, list[tuple[int, int, Any]]]) -> None:
    """A bag's /robot_description and /reference/robot_description: once each, the run's URDF
    (and the reference arm's), well-formed XML (xml.etree)."""
    urdf = _urdf()
    for topic, expected in ((ROBOT_DESCRIPTION, urdf),
                            (REFERENCE_DESCRIPTION, prefixed_urdf(urdf, REFERENCE_PREFIX))):
        ((_, _, msg),) = recorded[topic]
        assert msg.data == expected
        assert ET.fromstring(msg.data).tag == "robot"


def test_simulate_bag_shows_the_arm_as_the_live_view(tmp_path: Path) -> None:
    """``exo-ilc simulate --bag``'s bag read back: /tf per sample at its stamp equal to
    Pinocchio's forward kinematics of the recorded q (and of the feed-forward's q_d on the
    reference tree) to 1e-9; the URDFs once, well-formed; ``exo-ilc analyze`` reads it."""
    from exo_ilc_ros.bag import read_bag, write_run
    from exo_ilc_ros.core.session.learning_session import run_trials

    config = load_config(overrides={"trajectory.duration": 0.5, "max_trials": 2})
    result = run_trials(config, 0.10)
    bag = write_run(tmp_path / "sim", config, result)
    recorded = _bag_messages(bag)
    states = {_stamp(m): m for _, _, m in recorded[topics.JOINT_STATES]}
    profiles = {_stamp(m): m for _, _, m in recorded[topics.FEEDFORWARD]}
    assert len(states) == 2 * 51 and len(profiles) == 2
    _assert_tf_is_forward_kinematics([(log, m) for log, _, m in recorded[TF]], states,
                                     profiles)
    _assert_descriptions(recorded)
    run = read_bag(bag)
    assert sorted(run.trials) == [1, 2]
    np.testing.assert_array_equal(run.trials[2].position, result.records[1].position)


@pytest.fixture
def live_clients() -> LiveClients:
    """:class:`LiveClients` on a free port (the default 8765 may be held by another test
    session on the machine), started before the test starts its run."""
    return LiveClients()


def _bag_messages(bag: Path) -> dict[str, list[tuple[int, int, Any]]]:
    """Per topic: (log time, publish time, decoded message), from the bag's own schemas."""
    out: dict[str, list[tuple[int, int, Any]]] = {}
    for file in sorted(glob.glob(str(bag / "*.mcap"))):
        with open(file, "rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            for _, channel, message, decoded in reader.iter_decoded_messages():
                out.setdefault(channel.topic, []).append(
                    (message.log_time, message.publish_time, decoded))
    return out


def _stamp(msg: Any) -> int:
    stamp = msg.clock if hasattr(msg, "clock") else msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _decoded(received: Received) -> dict[str, list[tuple[int, Any]]]:
    """Every live message decoded from the schema its channel advertised, and nothing else."""
    out: dict[str, list[tuple[int, Any]]] = {}
    for channel in received.channels.values():
        assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
        decoder = generate_dynamic(channel["schemaName"], channel["schema"])[
            channel["schemaName"]]
        out[channel["topic"]] = [(log_time, decoder(payload))
                                 for log_time, payload in received.messages[channel["topic"]]]
    return out


def _topic_types(bag: Path) -> dict[str, str]:
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return {t["topic_metadata"]["name"]: t["topic_metadata"]["type"]
            for t in info["topics_with_message_count"]}


@pytest.mark.graph
def test_live_view_shows_what_the_bag_holds(tmp_path: Path, live_clients: LiveClients) -> None:
    """``exo-ilc run --live``: a WebSocket client subscribed to every advertised channel gets
    every JointState, trial summary and trial metrics the bag holds, equal; the URDF; /tf per
    sample equal to Pinocchio's forward kinematics (the arm and the reference) to 1e-9. The bag
    logs at the sim stamps; ``simulate --bag`` lists the same topics and types."""
    config_file = tmp_path / "short.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    port, received, late = live_clients.port, live_clients.received, live_clients.late
    run = live_clients.run(
        ["run", "--config", str(config_file), "--trials", "2", "--live", "--live-port",
         str(port),
         # every sample is asked for: by default the view shows a lock-step run at 200
         # samples per second of wall time (its display rate), not every sample
         "--live-rate", "0", "--bag-dir", str(tmp_path / "bags"), "--no-store", "--quiet"],
        timeout=240)
    assert run.returncode == 0, run.stderr[-3000:]
    live_clients.finish()
    assert live_clients.url in run.stderr
    (bag,) = list((tmp_path / "bags").iterdir())
    recorded = _bag_messages(bag)
    live = _decoded(received)
    assert SUBPROTOCOL == "foxglove.sdk.v1"
    assert "time" in received.server_info.get("capabilities", [])
    expected_channels = {topics.JOINT_STATES, topics.EFFORT_COMMANDS, topics.FEEDFORWARD,
                         topics.CLOCK, topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY,
                         topics.TRIAL_METRICS, topics.DIAGNOSTICS, ROBOT_DESCRIPTION,
                         REFERENCE_DESCRIPTION, TF}
    assert set(live) == expected_channels

    # The bag: log time = the sim stamp of every sample and /clock message.
    for topic in (topics.JOINT_STATES, topics.CLOCK, topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY):
        assert recorded[topic] and all(log == _stamp(m) for log, _, m in recorded[topic]), topic
    logs = [log for messages in recorded.values() for log, _, _ in messages]
    assert max(logs) < 10**12  # sim time (s since the run's start), not the wall clock

    # Every JointState, equal (and logged at its stamp live too).
    bag_states = {_stamp(m): m for _, _, m in recorded[topics.JOINT_STATES]}
    live_states = {_stamp(m): m for _, m in live[topics.JOINT_STATES]}
    assert all(log == _stamp(m) for log, m in live[topics.JOINT_STATES])
    assert sorted(live_states) == sorted(bag_states)
    for stamp, msg in bag_states.items():
        got = live_states[stamp]
        assert list(got.name) == list(msg.name)
        for field in ("position", "velocity", "effort"):
            assert list(getattr(got, field)) == list(getattr(msg, field)), (stamp, field)

    # Every trial result, equal: the numbers and the summaries.
    def metrics(messages: list[Any]) -> set[tuple[Any, ...]]:
        return {(tuple(d.label for d in m.layout.dim), m.layout.data_offset,
                 tuple(np.nan_to_num(np.asarray(m.data), nan=-1e300))) for m in messages}

    assert metrics([m for _, _, m in recorded[topics.TRIAL_METRICS]]) == \
        metrics([m for _, m in live[topics.TRIAL_METRICS]])
    assert len(recorded[topics.TRIAL_METRICS]) >= 2

    def summaries(messages: list[Any]) -> set[tuple[Any, ...]]:
        return {(s.name, s.level, s.message, s.hardware_id,
                 tuple((kv.key, kv.value) for kv in s.values))
                for m in messages for s in m.status}

    bag_summaries = summaries([m for _, _, m in recorded[topics.TRIAL_SUMMARY]])
    assert bag_summaries == summaries([m for _, m in live[topics.TRIAL_SUMMARY]])
    keys = [tuple(k for k, _ in s[4] if not k.startswith("aborted")) for s in bag_summaries]
    assert len(set(keys)) == 1  # every trial's summary has the same keys (trial 1's levels)

    # The late client got what came before it: the URDF and trial 1's metrics, again.
    late_live = _decoded(late)
    assert 1 in {int(m.data[0]) for _, m in late_live[topics.TRIAL_METRICS]}
    assert [m.data for _, m in late_live[ROBOT_DESCRIPTION]][:1] == [_urdf()]

    # The URDF, as the run's config makes it (and the reference arm's).
    urdf = _urdf()
    assert {m.data for _, m in live[ROBOT_DESCRIPTION]} == {urdf}
    reference_urdf = prefixed_urdf(urdf, REFERENCE_PREFIX)
    assert {m.data for _, m in live[REFERENCE_DESCRIPTION]} == {reference_urdf}

    # /tf: one message per sample at its stamp, the arm = Pinocchio's FK of the sample's q,
    # the reference = Pinocchio's FK of q_d at that sample of the trial's feed-forward; the
    # bag holds the same /tf as the view showed, and the same URDFs, once.
    profiles = {_stamp(m): m for _, _, m in recorded[topics.FEEDFORWARD]}
    _assert_tf_is_forward_kinematics(live[TF], bag_states, profiles)
    bag_tf = [(log, m) for log, _, m in recorded[TF]]
    _assert_tf_is_forward_kinematics(bag_tf, bag_states, profiles)
    assert sorted(_transform_values(m) for _, m in bag_tf) == \
        sorted(_transform_values(m) for _, m in live[TF])
    _assert_descriptions(recorded)

    # simulate --bag writes the same topics and types as the graph's recorder (simulate in
    # this process: no interpreter start-up).
    from exo_ilc_ros.cli.main import main as exo_ilc

    assert exo_ilc(["simulate", "--config", str(config_file), "--trials", "2", "--bag",
                    str(tmp_path / "sim")]) == 0
    (sim_bag,) = list((tmp_path / "sim").iterdir())
    assert _topic_types(sim_bag) == _topic_types(bag) == dict(topics.BAG_TYPES)
    sim_messages = _bag_messages(sim_bag)
    for topic in (topics.JOINT_STATES, topics.CLOCK):  # simulate logs at the stamps too
        assert all(log == _stamp(m) for log, _, m in sim_messages[topic])
    samples = len(profiles[min(profiles)].points)
    every = int(load_config()["clock_every"])
    per_trial = len([i for i in range(samples) if i % every == 0 or i == samples - 1])
    assert len(sim_messages[topics.CLOCK]) == 2 * per_trial  # as the plant sends /clock
    assert len(recorded[topics.CLOCK]) % per_trial == 0  # (a rerun attempt sends its own)
    assert {s.hardware_id for _, _, m in sim_messages[topics.DIAGNOSTICS] for s in m.status} == \
        {"computed_torque_controller"}


def test_port_zero_names_the_port_it_serves() -> None:
    """``--live-port 0`` picks a free port before the bridge starts, so the URL printed is
    the one to open (it used to print ws://127.0.0.1:0)."""
    with LiveView(load_config(), 0) as view:
        assert view.port > 0
        assert view.url == f"ws://127.0.0.1:{view.port}"
        assert f"port:={view.port}" in view.spec.arguments
        with socket.socket() as probe:  # free: the bridge can bind it
            probe.bind(("127.0.0.1", view.port))
    assert LiveView(load_config(), 8765).port == 8765


# ---- the layout made for the arm, meshes, late viewers (issue: the live view of any arm) ----

PANDA = ROOT / "config" / "arms" / "panda.yaml"
METRIC_IN_TITLE = {"max |e|": "max_abs_error", "RMS e": "rms_error", "step gain M": "level/M",
                   "damping B": "identified/viscous"}
"""An independent reading of each per-trial plot's title: the metrics row it must show."""


def test_shipped_layouts_are_the_generators() -> None:
    """config/layouts/ are ``exo-ilc layout``'s output for the shipped (paper) arm."""
    from exo_ilc_ros.orchestration.live_layout import arm_layout, foxglove_json, plotjuggler_xml

    arm = arm_layout(load_config())
    layouts = ROOT / "config" / "layouts"
    assert (layouts / "foxglove.json").read_text() == foxglove_json(arm, "foxglove")
    assert (layouts / "lichtblick.json").read_text() == foxglove_json(arm, "lichtblick")
    assert (layouts / "plotjuggler.xml").read_text() == plotjuggler_xml(arm)
    ET.fromstring((layouts / "plotjuggler.xml").read_text())  # well-formed


def _metrics_message(names: list[str]) -> Any:
    """A Float64MultiArray as the supervisor sends it, every entry distinct: value of
    (row r, joint j) = 100 r + j + 0.5, decoded back through the CDR the server forwards."""
    values = {"trial": "7"}
    rows = {"max_abs_error": 0, "metric/rms_error": 1, "level/M": 4, "identified/viscous": 7}
    for prefix, r in rows.items():
        for j, n in enumerate(names):
            values[f"{prefix}/{n}"] = str(100 * r + j + 0.5)
            values[f"identified/viscous/identifiable/{n}"] = "true"
    array = trial_metrics(values, names, warn=False)
    store = typestore()
    msg_type = store.types["std_msgs/msg/Float64MultiArray"]
    layout = store.types["std_msgs/msg/MultiArrayLayout"](
        dim=[store.types["std_msgs/msg/MultiArrayDimension"](label=d.label, size=d.size,
                                                             stride=d.stride)
             for d in array.dims], data_offset=array.data_offset)
    raw = store.serialize_cdr(msg_type(layout=layout, data=np.asarray(array.data)),
                              "std_msgs/msg/Float64MultiArray")
    return store.deserialize_cdr(raw, "std_msgs/msg/Float64MultiArray")


def _resolve(path: str, messages: dict[str, Any]) -> float:
    """A Plot series path (``/topic.field[i]``) read the way the app reads it."""
    topic, _, rest = path.partition(".")
    field, _, at = rest.partition("[")
    return float(getattr(messages[topic], field)[int(at.rstrip("]"))])


@pytest.mark.parametrize("config_file", [None, PANDA], ids=["paper", "panda"])
@pytest.mark.parametrize("identification", [False, True])
def test_generated_layout_names_the_arms_joints_and_draws_each_titled_metric(
        config_file: Path | None, identification: bool, tmp_path: Path) -> None:
    """The layout ``exo-ilc layout`` writes, read as the app reads it: per app its title key,
    every plot's series labelled with the arm's joints in order, each path resolving (against
    messages decoded from the schemas the server advertises) to the joint's value of the
    metric the title names; the 3D panel follows the URDF's root link; no B plot without
    identification."""
    from exo_ilc_ros.cli.main import main

    given = yaml.safe_load(config_file.read_text()) if config_file is not None else {}
    supervisor = given.setdefault("ilc_supervisor", {}).setdefault("ros__parameters", {})
    supervisor.setdefault("identification", {})["enabled"] = identification
    overlay = tmp_path / "arm.yaml"
    overlay.write_text(yaml.safe_dump(given))
    config = load_config(overlay)
    names = list(config["joint_names"])
    assert len(names) == (3 if config_file is None else 7)
    metrics = _metrics_message(names)
    decoded = decode([d.label for d in metrics.layout.dim], metrics.layout.data_offset,
                     list(metrics.data))
    store = typestore()
    state = store.types["sensor_msgs/msg/JointState"](
        header=store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""),
        name=names, position=np.arange(len(names)) + 0.25, velocity=np.zeros(len(names)),
        effort=np.zeros(len(names)))
    for app, key in (("foxglove", "foxglovePanelTitle"), ("lichtblick", "lichtblickPanelTitle")):
        out = tmp_path / f"{app}.json"
        assert main(["layout", "--config", str(overlay), "--app", app, "-o", str(out)]) == 0
        layout = json.loads(out.read_text())
        panels = layout["configById"]
        root = ET.fromstring(_urdf_of(config))
        children = {c.get("link") for c in root.iter("child")}
        assert panels["3D!arm"]["followTf"] in \
            {link.get("name") for link in root.findall("link")} - children
        shown = set()
        for panel_id, panel in panels.items():
            assert key in panel, panel_id  # every panel titled for this app
            if not panel_id.startswith("Plot!"):
                continue
            assert [p["label"] for p in panel["paths"]] == names, panel_id
            title = panel[key]
            rows = [row for text, row in METRIC_IN_TITLE.items() if text in title]
            if panel.get("xAxisVal") == "custom":  # per trial, x = the trial
                assert _resolve(panel["xAxisPath"]["value"], {topics.TRIAL_METRICS: metrics}) \
                    == 7
                (row,) = rows
                shown.add(row)
                for p in panel["paths"]:
                    got = _resolve(p["value"], {topics.TRIAL_METRICS: metrics})
                    assert got == decoded[row][p["label"]], (title, p)  # type: ignore[index]
            elif panel["paths"][0]["value"].startswith(topics.JOINT_STATES):
                for j, p in enumerate(panel["paths"]):
                    assert state.name[j] == p["label"]
                    assert _resolve(p["value"], {topics.JOINT_STATES: state}) == j + 0.25
        assert ("identified/viscous" in shown) == identification
        assert ("level/M" in shown) == (config["law"] == "sign")  # the only law with M
        assert {"max_abs_error", "rms_error"} <= shown


def _urdf_of(config: Any) -> str:
    from exo_ilc_ros.core.arm.build import view_urdf

    return view_urdf(config)[0]


def _bridge(config_file: Path, relay: Path | None = None, scheduling: str = "normal",
            stderr: Any = None) -> tuple[subprocess.Popen[str], int]:
    """foxglove_bridge alone, on a free port (fed by ``relay`` if given)."""
    args = [sys.executable, "-m", "exo_ilc_ros.nodes.foxglove_bridge", "--ros-args",
            "-p", "port:=0", "-p", f"config_file:={config_file}", "-p",
            f"scheduling:={scheduling}"]
    if relay is not None:
        args += ["-p", f"relay:={relay}", "-p", "sample_rate:=0.0"]
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=stderr, text=True)
    assert process.stdout is not None
    for line in process.stdout:
        if line.startswith('{"foxglove_port": '):
            return process, int(json.loads(line)["foxglove_port"])
    raise AssertionError(f"the bridge did not start: {process.wait()}")


async def _fetch_assets(url: str, uris: list[str]) -> tuple[dict[str, Any], list[Any]]:
    import websockets

    async with websockets.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                  max_size=None) as ws:
        info: dict[str, Any] = {}
        while not info:
            frame = await ws.recv()
            if isinstance(frame, str) and json.loads(frame).get("op") == "serverInfo":
                info = json.loads(frame)
        for request, uri in enumerate(uris):
            await ws.send(json.dumps({"op": "fetchAsset", "uri": uri, "requestId": request}))
        answers: list[Any] = [None] * len(uris)
        while any(a is None for a in answers):
            frame = await ws.recv()
            if isinstance(frame, bytes) and frame[0] == 0x04:  # fetch asset response
                request, status, length = struct.unpack_from("<IBI", frame, 1)
                text = frame[10:10 + length].decode()
                answers[request] = (status, text, bytes(frame[10 + length:]))
        return info, answers


@pytest.mark.graph
def test_the_panda_meshes_are_fetched_through_the_protocol_and_traversal_refused() -> None:
    """fetchAsset of the Panda URDF's own URI returns the mesh file's bytes (the
    example-robot-data wheel's); a ``..`` out of the package, a file outside the roots and a
    symlink-free absolute path elsewhere are refused."""
    import asyncio

    from exo_ilc_ros.core.arm.assets import package_share

    share = package_share("example-robot-data")
    if share is None:
        pytest.skip("example-robot-data (the Panda's meshes) is not installed")
    uri = "package://example-robot-data/robots/panda_description/meshes/visual/link0.dae"
    assert uri in (ROOT / "urdf" / "panda.urdf").read_text()
    mesh = (share / "robots/panda_description/meshes/visual/link0.dae").read_bytes()
    process, port = _bridge(PANDA)
    try:
        info, answers = asyncio.run(_fetch_assets(f"ws://127.0.0.1:{port}", [
            uri, "package://example-robot-data/../../../../../../etc/passwd", "file:///etc/passwd",
            "../../../../../../etc/passwd", "package://no_such_package/x.dae"]))
    finally:
        process.terminate()
        process.wait(timeout=30)
    assert "assets" in info["capabilities"]
    assert answers[0] == (0, "", mesh)
    assert all(status == 1 and data == b"" for status, _, data in answers[1:])


@pytest.mark.graph
def test_a_late_viewer_gets_every_trials_metrics_and_the_current_trials_samples(
        tmp_path: Path) -> None:
    """The bridge fed 10 trials of a run (feed-forward, samples, metrics, as the recorder's
    relay hands them), then trial 11's first samples: a viewer connecting now receives the
    10 trials' metrics and trial 11's samples from its first, not the earlier trials'."""
    from exo_ilc_ros.bag.messages import header, serialize
    from exo_ilc_ros.wire.cdr import JointStateWriter
    from exo_ilc_ros.wire.relay import RelaySender

    config = load_config()
    names = list(config["joint_names"])
    store = typestore()
    relay = tmp_path / "relay.sock"
    process, port = _bridge(ROOT / "config" / "exo_ilc.yaml", relay)
    writer = JointStateWriter(names)
    sender = RelaySender(relay, topics.PER_SAMPLE)
    sent: dict[int, list[int]] = {}
    try:
        metrics_type = "std_msgs/msg/Float64MultiArray"
        for trial in range(1, 12):
            t0 = trial * 10_000_000_000
            profile = store.types["trajectory_msgs/msg/JointTrajectory"](
                header=header(t0), joint_names=names, points=[])
            messages = [(t0, topics.FEEDFORWARD,
                         serialize(profile, "trajectory_msgs/msg/JointTrajectory"))]
            stamps = [t0 + i * 10_000_000 for i in range(50 if trial < 11 else 20)]
            sent[trial] = stamps
            messages += [(s, topics.JOINT_STATES, writer.write(s, np.full(3, i * 0.01),
                                                                np.zeros(3), np.zeros(3)))
                         for i, s in enumerate(stamps)]
            if trial < 11:
                array = store.types[metrics_type](
                    layout=store.types["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=2),
                    data=np.array([float(trial), 0.0]))
                messages.append((stamps[-1], topics.TRIAL_METRICS,
                                 serialize(array, metrics_type)))
            sender.send(messages)
            sender.flush()
        # the bridge has taken the whole feed once a probe viewer is sent trial 11's last
        # sample (whatever the machine's speed); then the late viewer connects
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline:
            probe = _decoded(collect(f"ws://127.0.0.1:{port}", duration=1.0))
            states = probe.get(topics.JOINT_STATES, [])
            if states and states[-1][0] == sent[11][-1]:
                break
        received = collect(f"ws://127.0.0.1:{port}", duration=5.0)
    finally:
        sender.close()
        process.terminate()
        process.wait(timeout=30)
    decoded = _decoded(received)
    assert sorted(int(m.data[0]) for _, m in decoded[topics.TRIAL_METRICS]) == \
        list(range(1, 11))
    assert [log for log, _ in decoded[topics.JOINT_STATES]] == sent[11]
    assert [_stamp(m) for _, m in decoded[topics.JOINT_STATES]] == sent[11]


@pytest.mark.graph
def test_live_pace_changes_only_the_wall_time(tmp_path: Path) -> None:
    """``run --live --live-pace 2``: the lock-step plant steps at most 2 simulated s per wall
    s. In the bag (publish time = the wall time the recorder received a sample), the two 1-s
    trials' samples span at least 1 s of wall time less the first's delivery (a lower
    bound the pace sets, whatever the machine's speed; unpaced, they take tens of ms), and
    every per-trial number equals simulate's (to 1e-9, the graph's rule)."""
    config_file = tmp_path / "short.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    graph_json, local_json = tmp_path / "graph.json", tmp_path / "local.json"
    main_args = [sys.executable, "-m", "exo_ilc_ros.cli.main"]
    result = subprocess.run([*main_args, "run", "--no-store", "--live", "--live-port", "0",
                             "--live-pace", "2", "--config", str(config_file), "--trials", "2",
                             "--bag-dir", str(tmp_path / "bags"), "--json", str(graph_json)],
                            text=True, capture_output=True, timeout=300, cwd=tmp_path,
                            stdin=subprocess.DEVNULL, check=False)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "foxglove_layout.json" in result.stderr  # the layout made for the run, offered
    from exo_ilc_ros.cli.main import main as exo_ilc  # simulate in this process: no start-up

    assert exo_ilc(["simulate", "--config", str(config_file), "--trials", "2", "--json",
                    str(local_json)]) == 0
    (g,), (r,) = json.loads(graph_json.read_text())["runs"], \
        json.loads(local_json.read_text())["runs"]
    assert len(g["trials"]) == len(r["trials"]) == 2
    for key in ("max_abs_error", "max_abs_feedforward", "max_abs_effort"):
        np.testing.assert_allclose([t[key] for t in g["trials"]], [t[key] for t in r["trials"]],
                                   rtol=0.0, atol=1e-9, err_msg=key)
    (bag,) = list((tmp_path / "bags").iterdir())
    states = sorted((_stamp(m), published) for _, published, m in
                    _bag_messages(bag)[topics.JOINT_STATES])
    sim, wall = states[-1][0] - states[0][0], states[-1][1] - states[0][1]
    assert sim >= 1.99e9  # two 1-s trials (their samples, consecutive in sim time)
    # paced: >= sim / 2 less the first sample's delivery delay (0.2 s of slack); unpaced
    # the 200 samples take tens of ms even at 1 000 steps per second
    assert wall >= sim / 2.0 - 0.2e9, (sim, wall)


def test_pace_waits_until_each_samples_wall_time() -> None:
    """The plants' pace (our plant's trials and MuJoCo's free-running plant alike): a sample
    0.4 simulated s after the one it counts from is published no earlier than 0.1 wall s later
    at pace 4 (a lower bound: sleeping never ends early); pace 0 never waits (a wait of 1e9
    simulated s returns)."""
    from exo_ilc_ros.nodes.plant_base import Pace

    pace = Pace(4.0)
    pace.start(1_000_000_000)
    start = time.monotonic_ns()
    pace.wait(1_400_000_000)
    assert time.monotonic_ns() - start >= 0.1e9
    unpaced = Pace(0.0)
    unpaced.start(0)
    unpaced.wait(10**18)


def test_live_pace_needs_live_and_a_rate(capsys: pytest.CaptureFixture[str]) -> None:
    """``--live-pace`` without ``--live`` is refused, naming the flag; a negative pace too;
    the pace is not part of the store's key (a paced run resumes an unpaced one's store)."""
    from exo_ilc_ros.cli.main import main
    from exo_ilc_ros.core.persistence.store import keyed_values

    assert main(["run", "--live-pace", "1"]) == 2
    assert "--live-pace: needs --live" in capsys.readouterr().err
    assert main(["run", "--live", "--live-pace", "-1"]) == 2
    assert keyed_values(load_config(overrides={"pace": 3.0})) == keyed_values(load_config())


def test_assets_resolve_within_their_roots_only(tmp_path: Path) -> None:
    """Relative and ``file://`` URIs within the URDF's directory are served; ``..``, an
    absolute path elsewhere and a symlink inside the directory that points outside it are
    refused (resolved before the containment check)."""
    from exo_ilc_ros.core.arm.assets import AssetResolver

    arm = tmp_path / "arm"
    (arm / "meshes").mkdir(parents=True)
    (arm / "meshes" / "link.stl").write_bytes(b"solid link")
    (tmp_path / "secret.txt").write_text("not a mesh")
    (arm / "meshes" / "escape.stl").symlink_to(tmp_path / "secret.txt")
    (arm / "meshes" / "inside.stl").symlink_to(arm / "meshes" / "link.stl")
    resolver = AssetResolver(arm / "arm.urdf")
    assert resolver.fetch("meshes/link.stl") == b"solid link"
    assert resolver.fetch((arm / "meshes" / "link.stl").as_uri()) == b"solid link"
    assert resolver.fetch("meshes/inside.stl") == b"solid link"
    for refused in ("../secret.txt", "meshes/../../secret.txt", "meshes/escape.stl",
                    (tmp_path / "secret.txt").as_uri(), "http://example.com/x.stl",
                    "meshes/missing.stl", "meshes"):
        assert resolver.fetch(refused) is None, refused


@pytest.mark.graph
@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="no SCHED_IDLE on this system")
def test_the_bridge_starts_at_its_priority_then_serves_below_the_loop(tmp_path: Path) -> None:
    """The bridge starts (imports, middleware, server) at the priority it was given, so a
    busy machine cannot starve its start (a graph run waits for it), and once it serves every
    thread of it runs at SCHED_IDLE (default ``scheduling``), as its log line says."""
    from exo_ilc_ros.nodes.realtime import thread_policies

    log = tmp_path / "bridge.err"
    with log.open("w") as err:
        process, _ = _bridge(ROOT / "config" / "exo_ilc.yaml", scheduling="idle", stderr=err)
    try:
        policies = thread_policies(process.pid)
        assert len(policies) > 1, policies  # the middleware's and the server's threads too
        assert set(policies.values()) == {os.SCHED_IDLE}, policies
    finally:
        process.terminate()
        process.wait(timeout=30)
    assert "scheduling: SCHED_IDLE" in log.read_text()


# ---- a person strapped in: the cuffs' forces live and in the layouts (issue 34) ----

ELBOW = ROOT / "config" / "myoelbow.yaml"
SHORT_PERSON = ('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 0.5\n'
                'plant_simulator:\n  ros__parameters:\n    musculoskeletal:\n'
                '      settle_time: 0.2\n')
"""Laid over config/myoelbow.yaml: 0.5 s trials, 0.2 s of settling (a short graph)."""


def _wrench_message(force: tuple[float, float, float]) -> Any:
    store = typestore()
    vector = store.types["geometry_msgs/msg/Vector3"]
    return store.types["geometry_msgs/msg/WrenchStamped"](
        header=store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""),
        wrench=store.types["geometry_msgs/msg/Wrench"](force=vector(*force),
                                                       torque=vector(0.0, 0.0, 0.0)))


def test_a_persons_layout_draws_each_cuffs_force_per_sample_and_per_trial(
        tmp_path: Path) -> None:
    """``exo-ilc layout`` for the elbow model: per trial each cuff's peak and RMS |F|, the
    path resolving against a metrics message with cuff values (decoded by its labels) to that
    cuff's value; per sample each cuff's force components from its wrench topic; PlotJuggler
    the same entries; a run without a person has no cuff plot (above)."""
    from exo_ilc_ros.cli.main import main
    from exo_ilc_ros.core.person.cuffs import CUFF_METRICS, CUFFS
    from exo_ilc_ros.orchestration.live_layout import _three_d

    config = load_config(ELBOW)
    names = list(config["joint_names"])
    values = {"trial": "7"}
    for c, cuff in enumerate(CUFFS):
        for m, metric in enumerate(CUFF_METRICS):
            values[f"cuff/{cuff}/{metric}"] = str(1000 + 10 * c + m + 0.5)
    array = trial_metrics(values, names, warn=False)
    store = typestore()
    layout_type = store.types["std_msgs/msg/MultiArrayLayout"]
    metrics = store.types["std_msgs/msg/Float64MultiArray"](
        layout=layout_type(dim=[store.types["std_msgs/msg/MultiArrayDimension"](
            label=d.label, size=d.size, stride=d.stride) for d in array.dims],
            data_offset=array.data_offset), data=np.asarray(array.data))
    decoded = decode([d.label for d in metrics.layout.dim], metrics.layout.data_offset,
                     list(metrics.data))["cuff"]
    assert isinstance(decoded, dict)
    wrenches = {topic: _wrench_message((c + 0.1, c + 0.2, c + 0.3))
                for c, topic in enumerate(topics.CUFF_WRENCHES)}
    out = tmp_path / "elbow.json"
    assert main(["layout", "--config", str(ELBOW), "-o", str(out)]) == 0
    panels = json.loads(out.read_text())["configById"]
    titles = {"peak cuff force": "peak_force_N", "RMS cuff force": "rms_force_N"}
    shown = set()
    for panel in panels.values():
        title = str(panel.get("foxglovePanelTitle", ""))
        metric = [m for text, m in titles.items() if title.startswith(text)]
        if metric:
            assert [p["label"] for p in panel["paths"]] == list(CUFFS)
            for p in panel["paths"]:
                got = _resolve(p["value"], {topics.TRIAL_METRICS: metrics})
                assert got == decoded[f"{p['label']}/{metric[0]}"], (title, p)
                shown.add((p["label"], metric[0]))
        elif title.startswith("cuff force on the person"):
            labels = [p["label"] for p in panel["paths"]]
            assert labels == [f"{c} F{a}" for c in CUFFS for a in "xyz"]
            for p in panel["paths"]:
                topic, _, field = p["value"].partition(".")
                c = topics.CUFF_WRENCHES.index(topic)
                assert p["label"].startswith(CUFFS[c])
                axis = field.rpartition(".")[2]
                assert getattr(wrenches[topic].wrench.force, axis) == \
                    (c + 0.1, c + 0.2, c + 0.3)["xyz".index(axis)]
                assert field == f"wrench.force.{axis}"
                shown.add((CUFFS[c], axis))
    assert shown == {(c, m) for c in CUFFS for m in (*titles.values(), "x", "y", "z")}
    person = panels["3D!arm"]["layers"]["person"]  # the person from its own URDF
    assert (person["layerId"], person["sourceType"], person["topic"]) == \
        ("foxglove.Urdf", "topic", topics.PERSON_DESCRIPTION)
    assert "person" not in _three_d("foxglove", "base_link")["layers"]
    xml = tmp_path / "elbow.xml"
    assert main(["layout", "--config", str(ELBOW), "--plotjuggler", "-o", str(xml)]) == 0
    curves = {c.get("name") for c in ET.parse(xml).iter("curve")}
    for cuff, topic in zip(CUFFS, topics.CUFF_WRENCHES, strict=True):
        assert {f"{topic}/wrench/force/{a}" for a in "xyz"} <= curves
        for metric in titles.values():
            entry = next(i for i, v in enumerate(metrics.data)
                         if v == float(values[f"cuff/{cuff}/{metric}"]))
            assert f"{topics.TRIAL_METRICS}/data[{entry}]" in curves
    plain = tmp_path / "plain.xml"
    assert main(["layout", "--plotjuggler", "-o", str(plain)]) == 0
    assert "/cuffs/" not in plain.read_text()


@pytest.mark.graph
@pytest.mark.parametrize("relayed", [True, False], ids=["relay", "dds"])
def test_the_live_view_forwards_a_persons_cuffs_and_draws_the_person(
        tmp_path: Path, relayed: bool, live_clients: LiveClients) -> None:
    """``exo-ilc run --live`` with the elbow model (2 trials of 0.5 s), fed by the recorder's
    relay or, with ``--no-bag``, reading DDS (reliable, so none is lost): the view advertises each
    ``/cuffs/<cuff>/wrench`` with its ros2msg schema and forwards every sample's wrench
    (every one at ``--live-rate 0``), logged at its stamp, equal to the bag's (relay) or to
    ``simulate``'s (DDS) wrench of that sample; and it draws the person: its URDF, its joints
    per sample and the person's /tf per sample, equal to the bag's (or simulate's)."""
    from exo_ilc_ros.bag import read_bag

    overlay = tmp_path / "short.yaml"
    overlay.write_text(SHORT_PERSON)
    port, received, late = live_clients.port, live_clients.received, live_clients.late
    storage = ["--bag-dir", str(tmp_path / "bags")] if relayed else [
        "--no-bag", "--live-param", "sample_reliability:=reliable"]  # no sample lost to DDS
    run = live_clients.run(
        ["run", "--config", str(ELBOW), "--scenario", str(overlay), "--trials", "2", "--live",
         "--live-port", str(port), "--live-rate", "0", *storage, "--no-store",
         "--live-pace", "1.0",  # trial 2 takes >= 0.5 s of wall time: the supervisor is
         "--quiet"], timeout=300)  # stopped for the late client before the run ends
    assert run.returncode == 0, run.stderr[-3000:]
    live_clients.finish()
    live = _decoded(received)
    # The late client got the person's URDF again.
    assert [m.data for _, m in _decoded(late)[topics.PERSON_DESCRIPTION]][:1] == \
        [m.data for _, m in live[topics.PERSON_DESCRIPTION]]
    for topic in topics.CUFF_WRENCHES:
        (channel,) = [c for c in received.channels.values() if c["topic"] == topic]
        assert channel["schemaName"] == "geometry_msgs/msg/WrenchStamped"
        assert all(log == _stamp(m) for log, m in live[topic])
    if relayed:
        (bag,) = list((tmp_path / "bags").iterdir())
        wrench = {k: t.cuff_wrench for k, t in read_bag(bag).trials.items()}
        samples = {_stamp(m): m for _, _, m in _bag_messages(bag)[topics.JOINT_STATES]}
    else:  # the graph's trials are the in-process ones (tested elsewhere): simulate's
        from exo_ilc_ros.cli.main import main as exo_ilc  # in this process: no start-up

        assert exo_ilc(["simulate", "--config", str(ELBOW), "--scenario", str(overlay),
                        "--trials", "2", "--bag", str(tmp_path / "sim")]) == 0
        (bag,) = list((tmp_path / "sim").iterdir())
        wrench = {k: t.cuff_wrench for k, t in read_bag(bag).trials.items()}
        samples = {_stamp(m): m for _, _, m in _bag_messages(bag)[topics.JOINT_STATES]}
    period = int(load_config(ELBOW)["control.period"] * 1e9)
    starts = sorted({_stamp(m) for _, m in live[topics.FEEDFORWARD]})[:2]  # (and the next's)
    assert len(starts) == 2 and sorted(wrench) == [1, 2]
    for c, topic in enumerate(topics.CUFF_WRENCHES):
        shown = {_stamp(m): m for _, m in live[topic]}
        assert sorted(shown) == sorted(samples)  # every sample's, at its stamp
        for stamp, msg in shown.items():
            k = max(i for i, t0 in enumerate(starts, start=1) if t0 <= stamp)
            w = wrench[k][(stamp - starts[k - 1]) // period, c]  # type: ignore[index]
            f, t = msg.wrench.force, msg.wrench.torque
            assert [f.x, f.y, f.z, t.x, t.y, t.z] == list(w), (topic, stamp)

    # The person drawn: its URDF (latched, once in the bag), its joints per sample and their
    # /tf, as the bag (relay) or simulate's bag (DDS: the in-process run) holds them.
    reference = _bag_messages(bag)
    ((_, _, description),) = reference[topics.PERSON_DESCRIPTION]
    assert {m.data for _, m in live[topics.PERSON_DESCRIPTION]} == {description.data}
    for topic, schema in ((topics.PERSON_DESCRIPTION, "std_msgs/msg/String"),
                          (topics.PERSON_JOINT_STATES, "sensor_msgs/msg/JointState")):
        (channel,) = [c for c in received.channels.values() if c["topic"] == topic]
        assert channel["schemaName"] == schema
    person = {_stamp(m): m for _, m in live[topics.PERSON_JOINT_STATES]}
    expected = {_stamp(m): m for _, _, m in reference[topics.PERSON_JOINT_STATES]}
    assert sorted(person) == sorted(expected) == sorted(samples)
    for stamp, msg in expected.items():
        got = person[stamp]
        assert list(got.name) == list(msg.name) and list(got.position) == list(msg.position)
        assert list(got.velocity) == list(msg.velocity)

    def person_tf(messages: list[Any]) -> dict[int, tuple[Any, ...]]:
        return {_stamp(m.transforms[0]): _transform_values(m) for m in messages
                if any(t.child_frame_id == PERSON_WORLD for t in m.transforms)}

    drawn = person_tf([m for _, m in live[TF]])
    assert sorted(drawn) == sorted(samples)
    assert drawn == person_tf([m for _, _, m in reference[TF]])
