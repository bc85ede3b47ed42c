"""The hand-written CDR of the control loop's messages against rclpy's own (no DDS)."""

from __future__ import annotations

import array

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from exo_ilc_ros.nodes.cdr import (
    CdrError,
    JointStateWriter,
    float64_array,
    read_float64_array,
    read_joint_state,
)


@pytest.mark.parametrize("names", [["a"], ["shoulder_flexion", "shoulder_abduction", "elbow"],
                                   ["j1", "j22", "j333", "j4444"]])
@pytest.mark.parametrize("frame_id", ["", "base", "odd"])
def test_joint_state_round_trip(names: list[str], frame_id: str) -> None:
    rng = np.random.default_rng(len(names))
    q, qd, effort = (rng.normal(size=len(names)) for _ in range(3))
    raw = JointStateWriter(names, frame_id).write(12_345_000_000_123, q, qd, effort)
    msg = deserialize_message(raw, JointState)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (12345, 123)
    assert list(msg.name) == names and msg.header.frame_id == frame_id
    assert list(msg.position) == list(q) and list(msg.velocity) == list(qd)
    assert list(msg.effort) == list(effort)
    stamp, position, velocity = read_joint_state(raw)
    assert stamp == 12_345_000_000_123
    assert position.tolist() == q.tolist() and velocity.tolist() == qd.tolist()


def test_reads_rclpy_joint_state_without_effort() -> None:
    msg = JointState(name=["x", "y"], position=array.array("d", [1.5, -2.0]),
                     velocity=array.array("d", [0.25, 4.0]))
    msg.header.frame_id = "f"
    msg.header.stamp.sec, msg.header.stamp.nanosec = 3, 7
    stamp, position, velocity = read_joint_state(serialize_message(msg))
    assert stamp == 3_000_000_007
    assert position.tolist() == [1.5, -2.0] and velocity.tolist() == [0.25, 4.0]


def test_float64_array_round_trip() -> None:
    values = np.array([1.0, -2.5, 3.25e-7])
    raw = float64_array(values)
    assert list(deserialize_message(raw, Float64MultiArray).data) == values.tolist()
    assert read_float64_array(raw).tolist() == values.tolist()
    msg = Float64MultiArray(data=array.array("d", values))
    msg.layout.dim = [MultiArrayDimension(label="joints", size=3, stride=3)]
    msg.layout.data_offset = 0
    assert read_float64_array(serialize_message(msg)).tolist() == values.tolist()


def test_truncated_message_is_an_error() -> None:
    raw = JointStateWriter(["a", "b"]).write(1, np.zeros(2), np.zeros(2), np.zeros(2))
    with pytest.raises(CdrError):
        read_joint_state(raw[:30])
    with pytest.raises(CdrError):
        read_float64_array(b"\x01\x00\x00\x00" + raw[4:])
