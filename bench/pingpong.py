"""Bare rclpy lock-step ping-pong: the middleware's own floor for the graph's control loop.

``ping`` publishes a JointState (3 joints, stamped, like the plant) and waits for the
Float64MultiArray reply of ``pong`` before the next; both spin an EventsExecutor with
``spin_once(timeout_sec=...)``. Run as two processes::

    python -m bench.pingpong pong [raw] &
    python -m bench.pingpong ping 3000 [raw]   # prints {"round_trips_per_s": ...} as JSON
    python -m bench.pingpong listen &          # optional: a third, silent subscriber
                                               # (then: ping 3000 [raw] listen)

``raw``: serialised CDR bytes both ways (``raw=True`` subscriptions, ``publish(bytes)``), as the
graph's hot paths do; without it, rclpy message objects.
"""

from __future__ import annotations

import array
import json
import sys
import time
from typing import Any

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from exo_ilc_ros.wire.cdr import JointStateWriter, float64_array, read_joint_state

QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
NAMES = ["j1", "j2", "j3"]


def pong(raw: bool) -> None:
    """Answer every JointState with a Float64MultiArray (``raw``: as CDR bytes, no message
    objects, the way the graph's nodes do it)."""
    node = Node("bench_pong")
    pub = node.create_publisher(Float64MultiArray, "/bench/commands", QOS)
    reply = Float64MultiArray()

    def on_state(msg: JointState) -> None:
        reply.data = array.array("d", msg.position)
        pub.publish(reply)

    def on_raw(data: bytes) -> None:
        pub.publish(float64_array(read_joint_state(data)[1]))

    node.create_subscription(JointState, "/bench/joint_states", on_raw if raw else on_state,
                             QOS, raw=raw)
    executor = EventsExecutor()
    executor.add_node(node)
    while rclpy.ok():
        executor.spin_once(timeout_sec=0.1)


def listen(commands: bool = True) -> None:
    """Subscribe to both topics (``commands`` False: the states only) and drain them every
    10 ms without waking per message (the recorder's :class:`~exo_ilc_ros.nodes.common.Inbox`):
    what one more subscriber process costs the ping-pong."""
    from exo_ilc_ros.nodes.common import INBOX_PERIOD, INBOX_QOS, Inbox

    owner = Node("bench_listener")
    inbox = Inbox(owner)
    inbox.subscribe(JointState, "/bench/joint_states", INBOX_QOS)
    if commands:
        inbox.subscribe(Float64MultiArray, "/bench/commands", INBOX_QOS)
    while rclpy.ok():
        time.sleep(INBOX_PERIOD)
        inbox.take()


def ping(count: int, raw: bool, warmup: int = 200, timeout: float = 60.0,
         listeners: int = 0) -> dict[str, float]:
    """``count`` timed round trips after ``warmup``; the rate and RTT percentiles."""
    node = Node("bench_ping")
    pub = node.create_publisher(JointState, "/bench/joint_states", QOS)
    replies = [0]
    node.create_subscription(Float64MultiArray, "/bench/commands",
                             lambda _msg: replies.__setitem__(0, replies[0] + 1), QOS, raw=raw)
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + timeout
    # pong and every listener matched before the first (volatile) message, else it is lost
    while pub.get_subscription_count() < 1 + listeners or \
            node.count_publishers("/bench/commands") < 1:
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() > deadline:
            raise RuntimeError("pong not discovered")
    state = JointState()
    state.name = NAMES
    writer = JointStateWriter(NAMES)
    effort = np.array([1.0, 2.0, 3.0])
    velocity = np.array([0.0, 0.1, 0.2])
    rtts = []
    start = 0.0
    for i in range(warmup + count):
        if i == warmup:
            start = time.perf_counter()
        sent = time.perf_counter()
        want = replies[0] + 1
        if raw:
            message: Any = writer.write(i * 10_000_000, np.array([0.1 * i, 0.2, 0.3]),
                                        velocity, effort)
        else:
            state.header.stamp.sec, state.header.stamp.nanosec = divmod(i * 10_000_000, 10**9)
            state.position = array.array("d", [0.1 * i, 0.2, 0.3])
            state.velocity = array.array("d", [0.0, 0.1, 0.2])
            state.effort = array.array("d", [1.0, 2.0, 3.0])
            message = state
        pub.publish(message)
        while replies[0] < want:
            executor.spin_once(timeout_sec=0.5)
            if i < warmup and time.perf_counter() - sent > 1.0:
                # pong's reply writer may not have matched our reader yet (discovery is per
                # pair, in both directions): the reply was lost, ask again
                pub.publish(message)
                sent = time.perf_counter()
            if time.monotonic() > deadline + 600:
                raise RuntimeError("lost a reply")
        if i >= warmup:
            rtts.append(time.perf_counter() - sent)
    elapsed = time.perf_counter() - start
    rtts.sort()
    return {"round_trips_per_s": count / elapsed, "rtt_p50_ms": rtts[len(rtts) // 2] * 1e3,
            "rtt_p99_ms": rtts[int(len(rtts) * 0.99)] * 1e3}


def main(argv: list[str] | None = None) -> int:
    """``pong [raw]`` or ``ping COUNT [raw]``."""
    args = sys.argv[1:] if argv is None else argv
    raw = "raw" in args
    rclpy.init()
    try:
        if args[0] == "pong":
            pong(raw)
        elif args[0] == "listen":
            listen(commands="states" not in args)
        else:
            print(json.dumps(ping(int(args[1]), raw, listeners=int("listen" in args))),
                  flush=True)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
