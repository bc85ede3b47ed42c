"""The Inbox (common.py): raw subscriptions no executor spins, drained in receive order."""

from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

pytestmark = pytest.mark.graph


def test_inbox_drains_two_topics_in_receive_order_and_is_never_spun() -> None:
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from exo_ilc_ros.nodes.cdr import float64_array, read_float64_array
    from exo_ilc_ros.nodes.common import Inbox

    rclpy.init()
    try:
        owner = Node("inbox_owner")
        inbox = Inbox(owner)
        assert inbox.node.get_name() == "inbox_owner_inbox"
        assert inbox.node.get_parameter("use_sim_time").value is False
        subs = [inbox.subscribe(Float64MultiArray, topic) for topic in ("/inbox_a", "/inbox_b")]
        pubs = [owner.create_publisher(Float64MultiArray, topic, 10)
                for topic in ("/inbox_a", "/inbox_b")]
        executor = EventsExecutor()
        executor.add_node(owner)
        deadline = time.monotonic() + 10.0
        while any(s.get_publisher_count() < 1 or p.get_subscription_count() < 1
                  for s, p in zip(subs, pubs, strict=True)):
            assert time.monotonic() < deadline, "inbox not matched"
            executor.spin_once(timeout_sec=0.05)
        for i in range(20):
            pubs[i % 2].publish(float64_array(np.array([float(i)])))
            time.sleep(0.002)
        end = time.monotonic() + 0.3
        while time.monotonic() < end:  # spinning the owner must not consume the inbox
            executor.spin_once(timeout_sec=0.05)
        taken = inbox.take()
        assert [t for _, t, _ in taken] == ["/inbox_a", "/inbox_b"] * 10
        assert [float(read_float64_array(raw)[0]) for _, _, raw in taken] == \
            [float(i) for i in range(20)]
        stamps = [s for s, _, _ in taken]
        assert stamps == sorted(stamps) and abs(stamps[0] - time.time_ns()) < 10e9
        assert inbox.take() == []
        inbox.destroy()
        owner.destroy_node()
    finally:
        rclpy.try_shutdown()
