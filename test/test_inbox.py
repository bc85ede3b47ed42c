"""The Inbox (common.py): raw subscriptions no executor spins, drained in receive order."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

pytestmark = pytest.mark.graph


def test_inbox_drains_two_topics_in_receive_order_and_is_never_spun() -> None:
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from exo_ilc_ros.nodes.common import Inbox
    from exo_ilc_ros.wire.cdr import float64_array, read_float64_array

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
        sent_from = time.time_ns()
        for i in range(20):
            pubs[i % 2].publish(float64_array(np.array([float(i)])))
            time.sleep(0.002)
        end = time.monotonic() + 0.3
        while time.monotonic() < end:  # spinning the owner must not consume the inbox
            executor.spin_once(timeout_sec=0.05)
        taken = inbox.take()
        taken_by = time.time_ns()
        assert [t for _, t, _ in taken] == ["/inbox_a", "/inbox_b"] * 10
        assert [float(read_float64_array(raw)[0]) for _, _, raw in taken] == \
            [float(i) for i in range(20)]
        stamps = [s for s, _, _ in taken]
        # receive times on the wall clock, between the first publish and the take
        assert stamps == sorted(stamps) and sent_from <= stamps[0] <= stamps[-1] <= taken_by
        assert inbox.take() == []
        inbox.destroy()
        owner.destroy_node()
    finally:
        rclpy.try_shutdown()


def test_inboxes_of_one_process_share_one_subscription_per_topic() -> None:
    """Two inboxes (the supervisor's and the recorder's in one container) on the same topic
    and QoS: one DDS subscription, each inbox gets every message exactly once whichever drains,
    the first destroyed leaves the second reading, and the last destroys the subscription."""
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from exo_ilc_ros.nodes.common import INBOX_QOS, Inbox
    from exo_ilc_ros.wire.cdr import float64_array, read_float64_array

    def values(taken: list[tuple[int, str, bytes]]) -> list[float]:
        return [float(read_float64_array(raw)[0]) for _, _, raw in taken]

    def wait(condition: Any) -> None:
        deadline = time.monotonic() + 10.0
        while not condition():
            assert time.monotonic() < deadline
            time.sleep(0.01)

    rclpy.init()
    try:
        owner = Node("shared_owner")
        first, second = Inbox(Node("first")), Inbox(Node("second"))
        sub = first.subscribe(Float64MultiArray, "/inbox_shared", INBOX_QOS)
        assert second.subscribe(Float64MultiArray, "/inbox_shared", INBOX_QOS) is sub
        other = second.subscribe(Float64MultiArray, "/inbox_other", INBOX_QOS)
        assert other is not sub
        pub = owner.create_publisher(Float64MultiArray, "/inbox_shared", 10)
        wait(lambda: pub.get_subscription_count() >= 1)
        time.sleep(0.2)
        assert pub.get_subscription_count() == 1
        for i in range(10):
            pub.publish(float64_array(np.array([float(i)])))
        got_first: list[float] = []
        wait(lambda: len(got_first.__iadd__(values(first.take()))) >= 10)
        assert got_first == [float(i) for i in range(10)]
        assert values(second.take()) == got_first  # its copy, taken once from DDS
        assert first.take() == [] and second.take() == []
        first.destroy()
        assert "first_inbox" in owner.get_node_names()  # still carries second's subscription
        pub.publish(float64_array(np.array([10.0])))
        got_second: list[float] = []
        wait(lambda: len(got_second.__iadd__(values(second.take()))) >= 1)
        assert got_second == [10.0]
        second.destroy()
        wait(lambda: pub.get_subscription_count() == 0)
        wait(lambda: not {"first_inbox", "second_inbox"} & set(owner.get_node_names()))
    finally:
        rclpy.try_shutdown()


def test_container_refuses_unknown_repeated_or_no_nodes(capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    """`container NODE ...` exits 2 with the usage before starting ROS for a name the package
    does not have, a node named twice, or no node; every name it lists can be built."""
    from exo_ilc_ros.nodes import container

    for argv, problem in ((["container"], "no node named"),
                          (["container", "ilc_supervisor", "plant", "--ros-args"],
                           "unknown node 'plant'"),
                          (["container", "bag_recorder", "bag_recorder"], "named twice")):
        assert container.main(argv) == 2
        err = capsys.readouterr().err
        assert problem in err and "usage: container NODE" in err
    for name in container.NODES:
        assert callable(container.node_factory(name))


def test_run_nodes_polls_stops_on_exit_code_and_drains_last() -> None:
    """run_nodes by protocol: a PollingNode is polled until it sets ``exit_code`` (the
    process's code), a DrainingNode is polled on after the stop and destroyed last, a plain
    node is neither polled nor drained."""
    from rclpy.node import Node

    from exo_ilc_ros.nodes import common

    log: list[str] = []

    class Plain(Node):
        def __init__(self) -> None:
            super().__init__("run_nodes_plain")

        def destroy_node(self) -> None:
            log.append("plain destroyed")
            super().destroy_node()

    class Failing(Node):
        def __init__(self) -> None:
            super().__init__("run_nodes_failing")
            self.exit_code: int | None = None
            self.polls = 0

        def poll(self) -> None:
            self.polls += 1
            if self.polls == 3:
                self.exit_code = 7

        def destroy_node(self) -> None:
            log.append(f"failing destroyed after {self.polls} polls")
            super().destroy_node()

    class Draining(Node):
        DRAINS_ON_STOP = True

        def __init__(self) -> None:
            super().__init__("run_nodes_draining")
            self.exit_code: int | None = None
            self.polls = 0
            self.drains = 0

        def poll(self) -> int:
            self.polls += 1
            return 0

        def drain(self) -> int:
            self.drains += 1
            return 0

        def destroy_node(self) -> None:
            log.append(f"draining destroyed after {self.polls} polls, {self.drains} drains")
            super().destroy_node()

    assert common.run_nodes([Plain, Failing, Draining], ["run_nodes"]) == 7
    from exo_ilc_ros.nodes import realtime  # its nodes' SCHED_FIFO requests stop with it

    assert realtime.fifo_scheduling(50) == (
        False, "normal (a node inside another program: its scheduling is left alone)")
    assert log[:2] == ["plain destroyed", "failing destroyed after 3 polls"]
    assert log[2].startswith("draining destroyed") and int(log[2].split()[3]) >= 3
    assert int(log[2].split()[5]) > 1  # drained on after the stop, not polled



def test_run_nodes_prints_the_counts_once_nothing_more_is_published(
        capfd: pytest.CaptureFixture[str]) -> None:
    """The published counts (what the recording-loss test holds against the bag) are printed
    only once a stopping node can publish no more. Messages that arrived while the process was
    stopping (here while the node's last poll sleeps) still have their callbacks run when the
    node leaves the executor; a count printed before that missed what they published (the
    soak once found one supervisor /diagnostics message more in the bag than counted)."""
    import json

    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from exo_ilc_ros.nodes import common

    final: dict[str, int] = {}

    class Echo(Node):
        """Echoes /run_nodes_src on /run_nodes_echo (counted), from a subscription."""

        def __init__(self) -> None:
            super().__init__("run_nodes_echo")
            self.exit_code: int | None = None
            self.source = self.create_publisher(Float64MultiArray, "/run_nodes_src", 100)
            self.echo = self.create_publisher(Float64MultiArray, "/run_nodes_echo", 100,
                                              publisher_class=common.CountingPublisher)
            self.create_subscription(Float64MultiArray, "/run_nodes_src",
                                     self.echo.publish, 100)
            self.polls = 0

        def poll(self) -> None:
            self.polls += 1
            if self.source.get_subscription_count() and self.polls > 20:
                for _ in range(20):
                    self.source.publish(Float64MultiArray())
                time.sleep(0.1)  # they arrive meanwhile: their callbacks wait in the executor
                self.exit_code = 3

        def destroy_node(self) -> None:
            final["echoed"] = self.echo.published
            super().destroy_node()

    assert common.run_nodes([Echo], ["run_nodes"]) == 3
    lines = [line for line in capfd.readouterr().err.splitlines()
             if line.startswith(f"{common.PUBLISHED_PREFIX}run_nodes_echo ")]
    assert len(lines) == 1
    printed = json.loads(lines[0].split(" ", 3)[3])
    assert final["echoed"] == 20  # the callbacks did run after the stop
    assert printed == {"/run_nodes_echo": 20}
