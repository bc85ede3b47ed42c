"""CDR bytes of the graph's messages (as :mod:`exo_ilc_ros.wire.topics` describes them) built
with rosbags' typestore, for bags written without the graph (their key-values:
:mod:`exo_ilc_ros.wire.protocol`).

Serialisation goes through ``typestore.serialize_cdr`` (exact sizes); never through rclpy's
``serialize_message``, whose buffers carry trailing bytes rosbags rejects.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from functools import cache
from typing import Any

import numpy as np

from ..wire import topics
from ..wire.protocol import feedforward_frame
from ..wire.publishers import CONTROLLER, SUPERVISOR
from ..wire.trial_metrics import trial_metrics as trial_metrics_array


@cache
def typestore() -> Any:
    """The ROS 2 Jazzy typestore of rosbags (loaded once)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def _type(name: str) -> Any:
    return typestore().types[name]


def time_msg(ns: int) -> Any:
    """``builtin_interfaces/msg/Time`` of ``ns`` nanoseconds."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return _type("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def time_ns(stamp: Any) -> int:
    """Nanoseconds of a ``Time`` (rosbags or rclpy message)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def serialize(msg: Any, msgtype: str) -> bytes:
    """CDR bytes of ``msg``."""
    return bytes(typestore().serialize_cdr(msg, msgtype))


def header(ns: int, frame_id: str = "") -> Any:
    """``std_msgs/msg/Header``."""
    return _type("std_msgs/msg/Header")(stamp=time_msg(ns), frame_id=frame_id)


def _f64(values: Any) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64)


def joint_state(ns: int, names: Sequence[str], position: Any, velocity: Any,
                effort: Any) -> bytes:
    """``/joint_states``: the sample at ``ns`` with the effort applied over the period that
    ended there."""
    msg = _type("sensor_msgs/msg/JointState")(
        header=header(ns), name=list(names), position=_f64(position),
        velocity=_f64(velocity), effort=_f64(effort))
    return serialize(msg, topics.TYPES[topics.JOINT_STATES])


def cuff_wrench(ns: int, cuff: int, wrench: Any) -> bytes:
    """``/cuffs/<cuff>/wrench`` (a person strapped in): cuff ``cuff``'s force (N) and torque
    (N m) on the person at the sample ``ns``, in the cuff's frame, as plant_simulator sends
    it."""
    vector = _type("geometry_msgs/msg/Vector3")
    w = [float(x) for x in wrench]
    msg = _type(topics.CUFF_TYPE)(
        header=header(ns, topics.CUFF_FRAMES[cuff]),
        wrench=_type("geometry_msgs/msg/Wrench")(force=vector(x=w[0], y=w[1], z=w[2]),
                                                 torque=vector(x=w[3], y=w[4], z=w[5])))
    return serialize(msg, topics.CUFF_TYPE)


def clock(ns: int) -> bytes:
    """``/clock``."""
    msg = _type("rosgraph_msgs/msg/Clock")(clock=time_msg(ns))
    return serialize(msg, topics.TYPES[topics.CLOCK])


def effort_command(effort: Any) -> bytes:
    """``/effort_controller/commands``: one effort per joint."""
    layout = _type("std_msgs/msg/MultiArrayLayout")(dim=[], data_offset=0)
    msg = _type("std_msgs/msg/Float64MultiArray")(layout=layout, data=_f64(effort))
    return serialize(msg, topics.TYPES[topics.EFFORT_COMMANDS])


def duration_msg(seconds: float) -> Any:
    """``builtin_interfaces/msg/Duration`` of ``seconds`` (rounded to whole nanoseconds)."""
    sec, nanosec = divmod(int(round(seconds * 1e9)), 1_000_000_000)
    return _type("builtin_interfaces/msg/Duration")(sec=sec, nanosec=nanosec)


def feedforward(ns: int, trial: int, names: Sequence[str], time: Any, position: Any,
                velocity: Any, u_ff: Any) -> bytes:
    """``/ilc/feedforward``: the profile of ``trial`` (q_d, qdot_d, u_ff per sample)."""
    point_type = _type("trajectory_msgs/msg/JointTrajectoryPoint")
    empty = np.zeros(0)
    q, qd, u = _f64(position), _f64(velocity), _f64(u_ff)
    points = [point_type(positions=q[i], velocities=qd[i], accelerations=u[i], effort=empty,
                         time_from_start=duration_msg(float(t)))
              for i, t in enumerate(np.asarray(time, dtype=float))]
    msg = _type("trajectory_msgs/msg/JointTrajectory")(
        header=header(ns, feedforward_frame(trial)),
        joint_names=list(names), points=points)
    return serialize(msg, topics.TYPES[topics.FEEDFORWARD])


def _diagnostics(ns: int, name: str, level: int, message: str,
                 values: Iterable[tuple[str, str]], hardware_id: str = SUPERVISOR) -> bytes:
    """A DiagnosticArray of one status; ``hardware_id`` the node that sends it in the graph."""
    key_value = _type("diagnostic_msgs/msg/KeyValue")
    status = _type("diagnostic_msgs/msg/DiagnosticStatus")(
        level=level, name=name, message=message,
        hardware_id=hardware_id, values=[key_value(key=k, value=v) for k, v in values])
    msg = _type("diagnostic_msgs/msg/DiagnosticArray")(header=header(ns), status=[status])
    return serialize(msg, topics.TYPES[topics.TRIAL_SUMMARY])


OK, WARN = 0, 1
"""DiagnosticStatus levels used by the summaries."""


def trial_event(ns: int, event: str, trial: int,
                values: Sequence[tuple[str, str]] = ()) -> bytes:
    """``/ilc/trial_events``: ``start``, ``end`` (with the summary's key-values), ``aborted``
    (``reason``: ``error_envelope`` with ``aborted_at``, or ``watchdog``), or ``finished`` /
    ``resumed`` (no trial number; values ``trials``)."""
    first = [] if event in ("finished", "resumed") else [("trial", str(trial))]
    return _diagnostics(ns, topics.TRIAL_STATUS, OK, event,
                        [*first, *((k, v) for k, v in values if k != "trial")])


def trial_summary(ns: int, values: Sequence[tuple[str, str]], within_bound: bool) -> bytes:
    """``/ilc/trial_summary``: level OK if every joint is within the bound, else WARN."""
    trial = dict(values).get("trial", "?")
    return _diagnostics(ns, topics.SUMMARY_STATUS, OK if within_bound else WARN,
                        f"trial {trial}", values)


def trial_metrics(values: Sequence[tuple[str, str]], names: Sequence[str],
                  within_bound: bool) -> bytes:
    """``/ilc/trial_metrics`` of a trial summary's key-values
    (:mod:`~exo_ilc_ros.wire.trial_metrics`)."""
    array = trial_metrics_array(dict(values), names, not within_bound)
    dimension = _type("std_msgs/msg/MultiArrayDimension")
    layout = _type("std_msgs/msg/MultiArrayLayout")(
        dim=[dimension(label=d.label, size=d.size, stride=d.stride) for d in array.dims],
        data_offset=array.data_offset)
    msg = _type("std_msgs/msg/Float64MultiArray")(layout=layout, data=_f64(array.data))
    return serialize(msg, topics.TYPES[topics.TRIAL_METRICS])


def controller_status(ns: int, message: str, values: Sequence[tuple[str, str]]) -> bytes:
    """``/diagnostics``: the controller's feed-forward acknowledgement (``loaded``) or trial
    report (``done``), as computed_torque_controller sends them."""
    name = topics.FEEDFORWARD_ACK_STATUS if message == "loaded" else \
        topics.CONTROLLER_TRIAL_STATUS
    return _diagnostics(ns, name, OK, message, values, CONTROLLER)
