"""The hand-written CDR of the control loop's messages against rclpy's own (no DDS)."""

from __future__ import annotations

import array
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from exo_ilc_ros.wire.cdr import (
    CdrError,
    JointStateWriter,
    float64_array,
    read_float64_array,
    read_joint_state,
    read_trajectory_positions,
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


def _trajectory(frame_id: str, names: list[str], widths: list[int], velocities: int,
                effort: list[int], seed: int = 0) -> tuple[bytes, np.ndarray | None]:
    """A serialised JointTrajectory (by rclpy) and its positions as rows (None if the points'
    widths differ)."""
    rng = np.random.default_rng(seed)
    msg = JointTrajectory()
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = 3, 7
    msg.joint_names = names
    rows = []
    for i, (width, effort_count) in enumerate(zip(widths, effort, strict=True)):
        rows.append(rng.normal(size=width))
        msg.points.append(JointTrajectoryPoint(
            positions=rows[-1].tolist(), velocities=rng.normal(size=velocities).tolist(),
            accelerations=rng.normal(size=width).tolist(),
            effort=rng.normal(size=effort_count).tolist(),
            time_from_start=Duration(sec=i, nanosec=5)))
    same = len(set(widths)) <= 1
    table = (np.array(rows).reshape(len(rows), -1) if rows else np.zeros((0, len(names)))) \
        if same else None
    return bytes(serialize_message(msg)), table


@pytest.mark.parametrize("frame_id", ["", "trial:12", "abcde"])
@pytest.mark.parametrize("names", [[], ["a"], ["shoulder_flexion", "shoulder_abduction", "elbow"]])
@pytest.mark.parametrize(("points", "width", "effort"), [(0, 3, 0), (1, 3, 0), (2, 3, 3),
                                                         (501, 3, 0), (501, 3, 3), (7, 1, 1),
                                                         (20, 2, 0), (5, 0, 0)])
def test_trajectory_positions_as_rclpy_wrote_them(frame_id: str, names: list[str], points: int,
                                                  width: int, effort: int) -> None:
    """read_trajectory_positions (the reference arm of the live view and the bags) reads the
    positions of every point, whatever padding the point's place gives its doubles."""
    for velocities in (0, width):
        raw, rows = _trajectory(frame_id, names, [width] * points, velocities, [effort] * points)
        stamp, got_names, positions = read_trajectory_positions(raw)
        assert stamp == 3_000_000_007 and got_names == names
        assert rows is not None and positions.shape == rows.shape
        assert positions.tolist() == rows.tolist()


def test_trajectory_points_of_other_layouts_and_damaged_profiles() -> None:
    """A point whose effort (so its padding) differs is read on its own, anywhere in the
    profile; points with different numbers of positions, and a cut message, are CdrErrors."""
    for where in (0, 1, 250, 499, 500):
        effort = [0] * 501
        effort[where] = 1
        raw, rows = _trajectory("", ["a", "b", "c"], [3] * 501, 3, effort, seed=where)
        assert rows is not None and read_trajectory_positions(raw)[2].tolist() == rows.tolist()
        widths = [3] * 501
        widths[where] = 4
        raw, _ = _trajectory("", ["a", "b", "c"], widths, 3, [0] * 501)
        with pytest.raises(CdrError, match="numbers of positions"):
            read_trajectory_positions(raw)
    raw, _ = _trajectory("", ["a", "b", "c"], [3] * 20, 3, [0] * 20)
    for cut in (5, 30, 200, 1000):  # (20 points end at byte 2136; rclpy adds bytes after)
        with pytest.raises(CdrError):
            read_trajectory_positions(raw[:cut])


def test_truncated_message_is_an_error() -> None:
    raw = JointStateWriter(["a", "b"]).write(1, np.zeros(2), np.zeros(2), np.zeros(2))
    with pytest.raises(CdrError):
        read_joint_state(raw[:30])
    with pytest.raises(CdrError):
        read_float64_array(b"\x01\x00\x00\x00" + raw[4:])


class _Logger:
    def error(self, message: str) -> None:
        pass


class _Node:
    def get_logger(self) -> _Logger:
        return _Logger()


def test_gate_fast_path_checks_what_the_full_check_does() -> None:
    """Once the plant's layout is learned, JointStateGate takes messages of that layout by two
    byte compares; non-finite values, stamps that do not increase and other names of the same
    length still get rejected, and reordered names still go through the full check."""
    from exo_ilc_ros.core.loop.wire_input import Cause
    from exo_ilc_ros.nodes.guard import JointStateGate, Rejections

    names = ["j1", "j2", "j3"]
    rejections = Rejections(_Node())  # type: ignore[arg-type]
    gate = JointStateGate(names, rejections)
    writer = JointStateWriter(names)
    zero = np.zeros(3)

    def raw(stamp: int, q: list[float], qd: list[float]) -> bytes:
        return writer.write(stamp, np.array(q), np.array(qd), zero)

    first = gate(raw(10, [0.1, 0.2, 0.3], [1.0, 2.0, 3.0]))  # full check, learns the layout
    assert first is not None and gate.layout is not None
    fast = gate(raw(20, [0.4, 0.5, 0.6], [4.0, 5.0, 6.0]))
    assert fast is not None and fast[0] == 20
    np.testing.assert_array_equal(fast[1], [0.4, 0.5, 0.6])
    np.testing.assert_array_equal(fast[2], [4.0, 5.0, 6.0])
    for bad in (raw(30, [0.1, np.nan, 0.3], [0.0, 0.0, 0.0]),
                raw(31, [0.1, 0.2, 0.3], [0.0, np.inf, 0.0]),
                raw(32, [1e308, 1e308, 0.0], [-np.inf, np.inf, 0.0]),
                raw(20, [0.1, 0.2, 0.3], [0.0, 0.0, 0.0])):  # stamp not after the last
        assert gate(bad) is None
    assert rejections.log.counts[Cause.NON_FINITE] == 3
    assert rejections.log.counts[Cause.NON_MONOTONIC_STAMP] == 1
    huge = gate(raw(40, [1e308, 1e308, 0.0], [0.0, 0.0, 0.0]))  # sum overflows: full check
    assert huge is not None and huge[0] == 40
    other = JointStateWriter(["k1", "k2", "k3"]).write(50, zero, zero, zero)  # same length
    assert gate(other) is None
    swapped = JointStateWriter(["j2", "j1", "j3"]).write(60, np.array([2.0, 1.0, 3.0]), zero,
                                                         zero)
    reordered = gate(swapped)
    assert reordered is not None
    np.testing.assert_array_equal(reordered[1], [1.0, 2.0, 3.0])


@pytest.mark.parametrize("window", [None, (1_000, 2_000)])
def test_gate_fast_and_full_paths_agree_on_stamps(window: tuple[int, int] | None) -> None:
    """The same message, stamp by stamp, through a gate that knows the layout (fast path) and
    through one that never saw it (full check): accepted or rejected alike, for stamps that are
    negative (sec = -1 once came back as -999999995 ns), repeated, older, in and outside the
    trial's window, and far in the future."""
    from exo_ilc_ros.nodes.guard import JointStateGate, Rejections

    names = ["j1", "j2", "j3"]
    writer = JointStateWriter(names)
    zero = np.zeros(3)
    stamps = [1_500, -1_000_000_000 + 5, -1, 0, 999, 1_000, 1_000, 1_500, 1_499, 2_000, 2_001,
              10**18, 1_700]
    fast = JointStateGate(names, Rejections(_Node()))  # type: ignore[arg-type]
    fast(writer.write(1_000 if window else 1, zero, zero, zero))  # learns the layout
    assert fast.layout is not None
    for stamp in stamps:
        fast.restart(window)
        full = JointStateGate(names, Rejections(_Node()))  # type: ignore[arg-type]
        full.restart(window)
        raw = writer.write(stamp, zero + 0.1, zero, zero)
        got_fast, got_full = fast(raw), full(raw)
        assert (got_fast is None) == (got_full is None), stamp
        if got_fast is not None and got_full is not None:
            assert got_fast[0] == got_full[0] == stamp
    for stamp in (-1, -1_000_000_000 + 5):
        fast.restart()
        assert fast(writer.write(stamp, zero, zero, zero)) is None, "negative stamps never pass"


def test_a_future_stamp_costs_one_message() -> None:
    """A well-formed JointState stamped far in the future, inside a trial: rejected (BAD_STAMP)
    and the trial's next samples still pass (before, it became the 'last stamp' and every later
    sample of the trial was rejected as not increasing)."""
    from exo_ilc_ros.core.loop.wire_input import Cause
    from exo_ilc_ros.nodes.guard import JointStateGate, Rejections

    names = ["j1", "j2", "j3"]
    writer = JointStateWriter(names)
    zero = np.zeros(3)
    rejections = Rejections(_Node())  # type: ignore[arg-type]
    gate = JointStateGate(names, rejections)
    gate.restart((10_000, 20_000))
    assert gate(writer.write(10_000, zero, zero, zero)) is not None
    assert gate(writer.write(10**15, zero, zero, zero)) is None
    assert gate(writer.write(11_000, zero, zero, zero)) is not None
    assert rejections.log.counts == {Cause.BAD_STAMP: 1}


def test_gate_fast_and_full_paths_agree_on_any_stamp_sequence() -> None:
    """Property (hypothesis, deterministic): for any sequence of stamps (sec over the whole
    int32 range, nanosec over uint32, so negative and far-future ones too), any trial window
    and restarts in between, a gate that knows the plant's layout (fast path) and one that is
    made to take the full check every time accept and reject exactly the same messages, with
    the same stamps."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from exo_ilc_ros.nodes.guard import JointStateGate, Rejections

    names = ["j1", "j2", "j3"]
    writer = JointStateWriter(names)
    zero = np.zeros(3)
    stamps = st.tuples(st.integers(-2**31, 2**31 - 1), st.integers(0, 2**32 - 1))
    windows = st.one_of(st.none(), st.tuples(st.integers(-10**10, 10**10),
                                             st.integers(0, 10**10)).map(
        lambda w: (w[0], w[0] + w[1])))
    steps = st.lists(st.one_of(stamps, windows.map(lambda w: ("restart", w))), max_size=30)

    @settings(max_examples=300, derandomize=True, database=None, deadline=None)
    @given(steps)
    def check(sequence: list[Any]) -> None:
        fast = JointStateGate(names, Rejections(_Node()))  # type: ignore[arg-type]
        full = JointStateGate(names, Rejections(_Node()))  # type: ignore[arg-type]
        fast(writer.write(0, zero, zero, zero))  # learns the layout
        fast.restart()
        assert fast.layout is not None
        for step in sequence:
            if step[0] == "restart":
                fast.restart(step[1])
                full.restart(step[1])
                continue
            sec, nanosec = step
            raw = bytearray(writer.write(0, zero + 0.5, zero, zero))
            raw[4:12] = np.array([sec], "<i4").tobytes() + np.array([nanosec], "<u4").tobytes()
            full.layout = None  # always the full check
            full.fast_names = None
            got_fast, got_full = fast(bytes(raw)), full(bytes(raw))
            assert (got_fast is None) == (got_full is None), (sec, nanosec)
            if got_fast is not None and got_full is not None:
                assert got_fast[0] == got_full[0] == sec * 1_000_000_000 + nanosec
                assert got_fast[0] >= 0
            assert fast.last_stamp_ns == full.last_stamp_ns

    check()
